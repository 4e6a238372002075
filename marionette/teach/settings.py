"""Teach-in settings (TOML): the rucksack, the filters, the working areas and the map
from the dancer's generalized coordinates to a figure's axes.

``marionette teach --settings TEACH.toml`` reads it; without ``--settings`` the bundled
``marionette/data/hoffmann1996_teach.toml`` (made for the bundled figure) is used.
Every table and key is optional; missing keys take the defaults below::

    [rucksack]
    half_side = 0.2            # b: half the side of the LED square [m]
    fit = "linear"             # "linear" (eq. 5.3-5.7) or "nonlinear" (Gauss-Newton)

    [triangulation]
    max_residual_px = 3.0      # drop LED points whose rms reprojection error is larger [pixel]

    [filter]
    cutoff_hz = 2.0            # -6 dB point of the 21-tap FIR low-pass at 12.5 Hz [Hz]
    max_gap_s = 2.0            # longest gap bridged; a longer one is an error [s] (0: no limit)

    [area]                     # working-area compression of x and y (filters.SoftLimit)
    dancer_center = [0.0, 0.0] # centre of the dancer's area [m]
    dancer_half = 2.0          # half side of the dancer's area [m] (4 m x 4 m)
    figure_center = [0.0, 0.0] # centre of the marionette's area [m]
    figure_half = 0.75         # half side of the marionette's area [m] (1.5 m x 1.5 m)
    knee_fraction = 0.6        # linear up to this fraction of figure_half [1]
    edge_fraction = 0.95       # the dancer's edge lands at this fraction of figure_half [1]

    [map]                      # marionette.teach.axis_map.AxisMap, same keys
    x_name = "x"
    ...
    [[map.winches]]
    name = "winch_head"
    attach = [0.0, 0.0, 0.35]  # body frame [m]
    gain = 1.0                 # [m/m]
    offset = 0.6               # axis value at the reference pose [m]
    [[map.lights]]
    pan_name = "light1_pan"
    ...

A ``[map]`` table replaces the whole default map (:class:`AxisMap` defaults apply to
keys it leaves out, including its default winches and lights).
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from .axis_map import AxisMap
from .filters import DEFAULT_CUTOFF, SoftLimit, soft_limit_for_areas
from .triangulate import DEFAULT_MAX_RESIDUAL_PX
from marionette.errors import ArgumentError, MarionetteError
from marionette.textfile import read_text

FITS = ("linear", "nonlinear")


class SettingsError(MarionetteError, ValueError):
    """Invalid teach settings; the message names the file and key."""


@dataclass
class TeachSettings:
    """Everything the teach-in needs besides cameras, recording and music."""

    half_side: float = 0.2                    # rucksack b [m]
    fit: str = "linear"                       # rucksack fit
    max_residual_px: float = DEFAULT_MAX_RESIDUAL_PX   # [pixel]
    cutoff_hz: float = DEFAULT_CUTOFF         # [Hz]
    max_gap_s: float | None = 2.0             # [s]; None: no limit
    dancer_center: tuple[float, float] = (0.0, 0.0)   # [m]
    dancer_half: float = 2.0                  # [m]
    figure_center: tuple[float, float] = (0.0, 0.0)   # [m]
    figure_half: float = 0.75                 # [m]
    knee_fraction: float = 0.6                # [1]
    edge_fraction: float = 0.95               # [1]
    axis_map: AxisMap = field(default_factory=AxisMap)
    source: str = "<defaults>"

    def compress(self, axis: int) -> SoftLimit:
        """Working-area compression of x (axis 0) or y (axis 1) [m -> m]."""
        return soft_limit_for_areas(self.dancer_center[axis], self.dancer_half,
                                    self.figure_center[axis], self.figure_half,
                                    self.knee_fraction, self.edge_fraction)


_SCHEMA = {
    "rucksack": {"half_side": "half_side", "fit": "fit"},
    "triangulation": {"max_residual_px": "max_residual_px"},
    "filter": {"cutoff_hz": "cutoff_hz", "max_gap_s": "max_gap_s"},
    "area": {k: k for k in ("dancer_center", "dancer_half", "figure_center", "figure_half",
                            "knee_fraction", "edge_fraction")},
}


def default_settings_path() -> Path:
    return Path(__file__).resolve().parent.parent / "data" / "hoffmann1996_teach.toml"


def _number(where: str, value, positive: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SettingsError(f"{where} = {value!r} is not a finite number")
    if positive and value <= 0:
        raise SettingsError(f"{where} = {value!r} must be > 0")
    return float(value)


def settings_from_dict(data: dict, source: str = "<memory>") -> TeachSettings:
    """Validate a parsed settings document; errors name the source and key."""
    unknown = sorted(set(data) - set(_SCHEMA) - {"map"})
    if unknown:
        raise SettingsError(f"{source}: unknown table(s) {unknown} "
                            f"(known: {', '.join([*_SCHEMA, 'map'])})")
    values: dict = {}
    for table, keys in _SCHEMA.items():
        section = data.get(table, {})
        if not isinstance(section, dict):
            raise SettingsError(f"{source}: [{table}] must be a table")
        for key, value in section.items():
            where = f"{source}: {table}.{key}"
            if key not in keys:
                raise SettingsError(f"{where} is not a known key (known: {', '.join(keys)})")
            if key == "fit":
                if value not in FITS:
                    raise SettingsError(f"{where} = {value!r} must be one of {FITS}")
                values[key] = value
            elif key in ("dancer_center", "figure_center"):
                if not isinstance(value, list) or len(value) != 2:
                    raise SettingsError(f"{where} = {value!r} must be [x, y] [m]")
                values[key] = tuple(_number(where, v, positive=False) for v in value)
            elif key == "max_gap_s":
                gap = _number(where, value, positive=False)
                if gap < 0:
                    raise SettingsError(f"{where} = {value!r} must be >= 0 (0: no limit)")
                values[key] = gap if gap > 0 else None
            else:
                values[key] = _number(where, value)
    try:
        settings = TeachSettings(**values, source=source)
        if "map" in data:
            if not isinstance(data["map"], dict):
                raise ArgumentError("[map] must be a table")
            settings.axis_map = AxisMap.from_dict(data["map"])
        settings.compress(0)                       # checks the area keys
    except (ValueError, TypeError) as exc:
        raise SettingsError(f"{source}: {exc}") from None
    return settings


def load_settings(path=None) -> TeachSettings:
    """Read teach settings; None gives the bundled settings for the bundled figure."""
    path = default_settings_path() if path is None else Path(path)
    try:
        data = tomllib.loads(read_text(path, SettingsError))
    except FileNotFoundError:
        raise SettingsError(f"{path}: no such file") from None
    except tomllib.TOMLDecodeError as exc:
        raise SettingsError(f"{path}: not valid TOML: {exc}") from None
    return settings_from_dict(data, os.fspath(path))
