"""cameras.toml: the identified cameras, written by ``marionette calibrate`` and read
by ``marionette teach``.

Format (TOML)::

    # units: a, b, c [m]; alpha, beta, gamma, delta, epsilon [rad];
    #        L, R0, T0 [pixel]; q3, q5, rho_max [1]
    [[camera]]                  # camera 0 (the camera column of the recording)
    a = -5.0012                 # position [m]
    b = -3.9987
    c = 3.0021
    alpha = -0.2011             # elevation [rad]
    beta = 0.0102               # roll [rad]
    gamma = -0.8963             # yaw [rad]
    L = 420.31                  # camera constant [pixel]
    R0 = 255.5                  # optical axis, column [pixel]
    T0 = 255.5                  # optical axis, row (upwards) [pixel]
    delta = 0.0                 # improved model (eq. 4.15-4.23)
    epsilon = 0.0
    q3 = 0.0
    q5 = 0.0
    rho_max = 0.862

    [camera.calibration]        # optional, informative: how it was identified
    method = "levenberg_marquardt"
    ...

    [camera.uncertainty]        # optional, informative: standard uncertainty [unit]
    a = 0.012
    ...

The tables are cameras 0, 1, ... in order.  Of the parameters only ``a, b, c`` are
required; missing ones take the defaults of
:class:`marionette.teach.camera.CameraParams`.  Instead of ``alpha, beta, gamma`` a
rough camera (for ``marionette calibrate --guess``) may give ``target = [x, y, z]``,
the point its view line passes through [m] (and optionally ``beta``).
"""

from __future__ import annotations

import math
import os
import tomllib
from typing import Sequence

from .camera import ALL_NAMES, UNITS, CameraParams, look_at
from marionette.errors import ArgumentError, MarionetteError
from marionette.textfile import read_text

INFO_TABLES = ("calibration", "uncertainty")


class CameraFileError(MarionetteError, ValueError):
    """cameras.toml is unreadable or invalid; the message names the file and camera."""


def read_cameras(path) -> list[CameraParams]:
    """Cameras of a cameras.toml file, in order (see the module docstring)."""
    path = os.fspath(path)
    try:
        data = tomllib.loads(read_text(path, CameraFileError))
    except FileNotFoundError:
        raise CameraFileError(f"{path}: no such file") from None
    except tomllib.TOMLDecodeError as exc:
        raise CameraFileError(f"{path}: not valid TOML: {exc}") from None
    return cameras_from_dict(data, path)


def cameras_from_dict(data: dict, path: str = "<cameras>") -> list[CameraParams]:
    unknown = sorted(set(data) - {"camera"})
    if unknown:
        raise CameraFileError(f"{path}: unknown top-level key(s) {unknown} (expected [[camera]] tables)")
    tables = data.get("camera")
    if not isinstance(tables, list) or not tables:
        raise CameraFileError(f"{path}: no [[camera]] tables")
    cameras = []
    for k, table in enumerate(tables):
        where = f"{path}: camera {k}"
        if not isinstance(table, dict):
            raise CameraFileError(f"{where}: not a table")
        params = {key: v for key, v in table.items() if key not in INFO_TABLES}
        target = params.pop("target", None)
        for key, value in params.items():
            if key not in ALL_NAMES:
                raise CameraFileError(f"{where}: unknown key {key!r} = {value!r} "
                                      f"(known: {', '.join(ALL_NAMES)}, target)")
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise CameraFileError(f"{where}: {key} = {value!r} is not a finite number "
                                      f"[{UNITS[key]}]")
        try:
            if target is not None:
                if "alpha" in params or "gamma" in params:
                    raise ArgumentError("give either target or the angles alpha, gamma, not both")
                if (not isinstance(target, list) or len(target) != 3
                        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in target)):
                    raise ArgumentError(f"target = {target!r} must be three numbers [m]")
                missing = [n for n in ("a", "b", "c") if n not in params]
                if missing:
                    raise ArgumentError(f"camera parameter {missing[0]!r} (position [m]) is missing")
                position = [params.pop(n) for n in ("a", "b", "c")]
                beta = params.pop("beta", 0.0)
                cameras.append(look_at(position, target, roll=beta, **params))
            else:
                cameras.append(CameraParams.from_dict(params))
        except ValueError as exc:
            raise CameraFileError(f"{where}: {exc}") from None
    return cameras


def _value(v) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    return repr(float(v))


def format_cameras(cameras: Sequence[CameraParams], info: Sequence[dict] | None = None,
                   uncertainty: Sequence[dict] | None = None, comment: str = "") -> str:
    """TOML text for the cameras, with optional per-camera information tables
    (``info[k]``: strings and numbers; ``uncertainty[k]``: parameter -> [unit])."""
    lines = [f"# {c}" for c in comment.splitlines()]
    lines += ["# units: a, b, c [m]; alpha, beta, gamma, delta, epsilon [rad];",
              "#        L, R0, T0 [pixel]; q3, q5, rho_max [1]"]
    for k, cam in enumerate(cameras):
        lines += ["", f"[[camera]]   # camera {k}"]
        lines += [f"{name} = {_value(getattr(cam, name))}" for name in ALL_NAMES]
        if info is not None and info[k]:
            lines += ["", "[camera.calibration]"]
            lines += [f"{key} = {_value(v)}" for key, v in info[k].items()]
        if uncertainty is not None and uncertainty[k]:
            lines += ["", "[camera.uncertainty]   # standard uncertainty [unit of the parameter]"]
            lines += [f"{key} = {_value(v)}" for key, v in uncertainty[k].items()]
    return "\n".join(lines) + "\n"


def write_cameras(path, cameras: Sequence[CameraParams], info=None, uncertainty=None,
                  comment: str = "") -> None:
    """Write cameras.toml; the text is checked to read back to the same cameras."""
    text = format_cameras(cameras, info, uncertainty, comment)
    back = cameras_from_dict(tomllib.loads(text), os.fspath(path))
    assert back == list(cameras), "cameras.toml does not read back"
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(text)
