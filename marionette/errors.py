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


class ArgumentError(MarionetteError, ValueError):
    """A function was given a value outside its domain: an input its caller
    passed on unchecked, or a programming error."""


class LineError(MarionetteError, ValueError):
    """A line of a text file is malformed; ``path``, ``line`` (1-based) and
    ``value`` say where."""

    def __init__(self, path, line: int, value: str, message: str):
        self.path = str(path)
        self.line = line
        self.value = value
        super().__init__(f"{self.path}, line {line}: {message} (value {value!r})")
