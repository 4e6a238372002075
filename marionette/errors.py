"""Exceptions the package raises; each message names the file, place and value at fault."""


class MarionetteError(Exception):
    """Base of the package's errors."""


class ConfigError(MarionetteError, ValueError):
    """A figure configuration (TOML) is invalid."""


class ShowError(MarionetteError, ValueError):
    """A show file is invalid, or does not fit the figure."""


class EngineError(MarionetteError, RuntimeError):
    """The C engine refused a request."""


class TeachError(MarionetteError, ValueError):
    """Teach-in input (markers, cameras, recording, settings) is invalid or unusable."""
