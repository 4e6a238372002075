"""marionette: a servo-driven figure dances a taught motion in step with music.

Python configures the figure and loads the taught show; a C engine runs the
20 ms tick in its own thread without the GIL.

The names below are imported when first used (PEP 562), so that a process
that needs only a part (the simulator: marionette.protocol) does not load
the engine.
"""
import importlib

__version__ = "0.1.0"

# public name -> the module that defines it
_WHERE = {
    "AxisConfig": "marionette.config", "FigureConfig": "marionette.config",
    "load_config": "marionette.config",
    "Engine": "marionette.engine", "Snapshot": "marionette.engine",
    "ConfigError": "marionette.errors", "EngineError": "marionette.errors",
    "MarionetteError": "marionette.errors", "ShowError": "marionette.errors",
    "Show": "marionette.show", "fit_to_figure": "marionette.show", "load_show": "marionette.show",
}
__all__ = sorted(_WHERE)


def __getattr__(name: str):
    if name not in _WHERE:          # a subpackage, as marionette.transport.open_link(...)
        try:
            return importlib.import_module(f"marionette.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"marionette.{name}":
                raise
            raise AttributeError(f"module 'marionette' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(_WHERE[name]), name)
    globals()[name] = value          # once found, an ordinary attribute
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
