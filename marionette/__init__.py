"""marionette: a servo-driven figure dances a taught motion in step with music.

Python configures the figure and loads the taught show; a C engine runs the
20 ms tick in its own thread without the GIL.
"""
from marionette.config import AxisConfig, FigureConfig, load_config
from marionette.engine import Engine, Snapshot
from marionette.errors import ConfigError, EngineError, MarionetteError, ShowError
from marionette.show import Show, fit_to_figure, load_show

__version__ = "0.1.0"
__all__ = ["AxisConfig", "ConfigError", "Engine", "EngineError", "FigureConfig", "MarionetteError",
           "Show", "ShowError", "Snapshot", "fit_to_figure", "load_config", "load_show"]
