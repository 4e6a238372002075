"""Every exception the package raises derives from MarionetteError, so that the
CLI's one catch turns each into a short message and exit status 2."""
import importlib
import inspect
import pkgutil
import re
from pathlib import Path

import marionette
from marionette.errors import MarionetteError

PACKAGE = Path(marionette.__file__).parent
# modules that need an optional extra or a display to import
OPTIONAL = {"marionette.music.sound_card"}


def _modules():
    for info in pkgutil.walk_packages([str(PACKAGE)], prefix="marionette."):
        if info.name not in OPTIONAL and not info.name.endswith("__main__"):
            yield importlib.import_module(info.name)


def test_every_exception_class_of_the_package_is_a_marionette_error():
    classes = {}
    for module in _modules():
        for name, obj in vars(module).items():
            if (inspect.isclass(obj) and issubclass(obj, BaseException)
                    and obj.__module__ == module.__name__ and not name.startswith("_")):
                classes[f"{module.__name__}.{name}"] = obj
    assert len(classes) >= 12          # ProtocolError, SettingsError, CameraFileError, LineError, ...
    strays = [name for name, cls in classes.items() if not issubclass(cls, MarionetteError)]
    assert strays == []


def test_no_builtin_value_or_runtime_error_is_raised():
    """ValueError and RuntimeError by name escape the CLI's catch: the package
    raises its own (ArgumentError is a ValueError too, for callers that catch one)."""
    found = []
    for path in sorted(PACKAGE.rglob("*")):
        if path.suffix in (".py", ".pyx"):
            for n, line in enumerate(path.read_text().splitlines(), 1):
                if re.search(r"\braise (ValueError|RuntimeError)\(", line):
                    found.append(f"{path.relative_to(PACKAGE)}:{n}: {line.strip()}")
    assert found == []
