"""Figure configuration: the axes, their servo behaviour models and limits.

A figure is a TOML file (format in docs/formats.md)::

    [figure]
    name = "..."
    tick_period = 0.020          # [s]

    [[axis]]
    name = "head"
    ...

All values are SI: positions in m (unit "m") or rad (unit "rad").
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path

from marionette.errors import ConfigError

UNITS = ("m", "rad")
DEFAULT_TICK_PERIOD = 0.020  # [s]


@dataclass(frozen=True)
class AxisConfig:
    """One servo axis: addressing, limits and behaviour model, all SI."""

    name: str
    node: int               # servo node address, 0..255
    channel: int            # axis channel on that node, 0..255
    unit: str               # "m" or "rad"
    min: float              # lower position limit [unit]
    max: float              # upper position limit [unit]
    home: float             # rest position [unit]
    max_speed: float        # top speed [unit/s]
    max_accel: float        # top acceleration [unit/s^2]
    dead_time: float        # pure delay of the servo [s]
    time_constant: float    # first-order lag tau [s]
    scale: float            # device counts per unit [counts/unit]
    offset: float = 0.0     # device counts at position 0 [counts]
    bandwidth: float | None = None  # small-signal bandwidth [Hz], informative

    @property
    def mean_delay(self) -> float:
        """Mean delay of dead time plus first-order lag [s] (the paper's lead)."""
        return self.dead_time + self.time_constant


FOLLOW_MODES = ("smooth", "paper")
ON_LOST = ("flywheel", "hold")      # what the show does while the music is not followed


@dataclass(frozen=True)
class FollowConfig:
    """Music following (optional [follow] table): how the playback position
    follows the live music. Times in s; marionette.follow turns them into
    ticks for the C follower (ext/mar_follow.h, docs/music.md)."""

    mode: str = "smooth"            # "smooth" (fractional rate) or "paper" (double or skip a sample)
    rate_min: float = 0.90          # slowest playback rate [1]
    rate_max: float = 1.10          # fastest playback rate [1]
    latency: float | None = None    # from the end of the newest loudness frame's audio to the tick [s];
                                    # None: not set (0, or a sound card's own input latency)
    window: float = 4.0             # tracking correlation window [s]
    lock_threshold: float = 0.6     # correlation a place needs to lock [1]
    lock_margin: float = 0.3        # its lead over any other place [Fisher z]
    lost_after: float = 3.0         # unclear music before searching the whole piece [s]
    pause_after: float = 0.16       # silence where music is expected before a pause [s]
    search_budget: int = 512        # search candidates scored per tick [1]
    range_db: float = 25.0          # loudness range below the running peak that counts [dB]
    on_lost: str = "flywheel"       # while the music is not followed: play on at the last rate
                                    # ("flywheel") or hold the place where it was lost ("hold")


@dataclass(frozen=True)
class FigureConfig:
    """A figure: its axes in order, the tick period, where it came from."""

    name: str
    tick_period: float              # [s]
    axes: tuple[AxisConfig, ...]
    source: str = "<memory>"        # file it was read from
    follow: FollowConfig = field(default_factory=FollowConfig)  # music following

    @property
    def axis_names(self) -> list[str]:
        return [a.name for a in self.axes]

    def axis(self, name: str) -> AxisConfig:
        for a in self.axes:
            if a.name == name:
                return a
        raise KeyError(f"{self.source}: no axis named {name!r}")


_REQUIRED = ("name", "node", "channel", "unit", "min", "max", "home", "max_speed",
             "max_accel", "dead_time", "time_constant", "scale")
_KNOWN = {f.name for f in fields(AxisConfig)}


def _number(src: str, key: str, value, *, positive=False, non_negative=False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{src}: {key} = {value!r} is not a number")
    value = float(value)
    if not math.isfinite(value):
        raise ConfigError(f"{src}: {key} = {value!r} is not finite")
    if positive and value <= 0:
        raise ConfigError(f"{src}: {key} = {value!r} must be > 0")
    if non_negative and value < 0:
        raise ConfigError(f"{src}: {key} = {value!r} must be >= 0")
    return value


def _integer(src: str, key: str, value, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ConfigError(f"{src}: {key} = {value!r} must be an integer in {lo}..{hi}")
    return value


def _axis(src: str, index: int, table: dict) -> AxisConfig:
    where = f"axis[{index}]"
    if not isinstance(table, dict):
        raise ConfigError(f"{src}: {where} is not a table")
    name = table.get("name")
    if name is not None:
        where = f"axis[{index}] ({name!r})"
    for key in _REQUIRED:
        if key not in table:
            raise ConfigError(f"{src}: {where} is missing the key {key!r}")
    for key in table:
        if key not in _KNOWN:
            raise ConfigError(f"{src}: {where}.{key} = {table[key]!r} is not a known key "
                              f"(known: {', '.join(sorted(_KNOWN))})")
    if not isinstance(name, str) or not name.isidentifier():
        raise ConfigError(f"{src}: {where}.name = {name!r} must be an identifier "
                          "(letters, digits, underscores)")
    unit = table["unit"]
    if unit not in UNITS:
        raise ConfigError(f"{src}: {where}.unit = {unit!r} is not a known unit (use one of {UNITS})")
    num = {k: _number(src, f"{where}.{k}", table[k]) for k in ("min", "max", "home", "offset")
           if k in table}
    lo, hi = num["min"], num["max"]
    if not lo < hi:
        raise ConfigError(f"{src}: {where} limits reversed or empty: min = {lo!r}, max = {hi!r}")
    if not lo <= num["home"] <= hi:
        raise ConfigError(f"{src}: {where}.home = {num['home']!r} is outside [{lo!r}, {hi!r}]")
    scale = _number(src, f"{where}.scale", table["scale"])
    if scale == 0:
        raise ConfigError(f"{src}: {where}.scale = 0 maps every position to the same count")
    bandwidth = table.get("bandwidth")
    return AxisConfig(
        name=name,
        node=_integer(src, f"{where}.node", table["node"], 0, 255),
        channel=_integer(src, f"{where}.channel", table["channel"], 0, 255),
        unit=unit, min=lo, max=hi, home=num["home"],
        max_speed=_number(src, f"{where}.max_speed", table["max_speed"], positive=True),
        max_accel=_number(src, f"{where}.max_accel", table["max_accel"], positive=True),
        dead_time=_number(src, f"{where}.dead_time", table["dead_time"], non_negative=True),
        time_constant=_number(src, f"{where}.time_constant", table["time_constant"], non_negative=True),
        scale=scale, offset=num.get("offset", 0.0),
        bandwidth=None if bandwidth is None
        else _number(src, f"{where}.bandwidth", bandwidth, positive=True),
    )


# [follow] keys: (lowest, highest) allowed, inclusive; None: no bound
_FOLLOW_RANGES = {"rate_min": (0.25, 1.0), "rate_max": (1.0, 4.0), "latency": (0.0, 10.0),
                  "window": (0.2, 60.0), "lock_threshold": (0.0, 0.99), "lock_margin": (0.0, 1.9),
                  "lost_after": (0.0, None), "pause_after": (0.02, None), "range_db": (1.0, 200.0)}


def _follow(src: str, table) -> FollowConfig:
    """The optional [follow] table; defaults for what it leaves out."""
    if not isinstance(table, dict):
        raise ConfigError(f"{src}: [follow] must be a table")
    known = {f.name for f in fields(FollowConfig)}
    for key in table:
        if key not in known:
            raise ConfigError(f"{src}: follow.{key} = {table[key]!r} is not a known key "
                              f"(known: {', '.join(sorted(known))})")
    values = {}
    if "mode" in table:
        if table["mode"] not in FOLLOW_MODES:
            raise ConfigError(f"{src}: follow.mode = {table['mode']!r} is not a known mode "
                              f"(use one of {FOLLOW_MODES})")
        values["mode"] = table["mode"]
    if "on_lost" in table:
        if table["on_lost"] not in ON_LOST:
            raise ConfigError(f"{src}: follow.on_lost = {table['on_lost']!r} is not known "
                              f"(use one of {ON_LOST})")
        values["on_lost"] = table["on_lost"]
    if "search_budget" in table:
        values["search_budget"] = _integer(src, "follow.search_budget", table["search_budget"], 1, 100000)
    for key, (lo, hi) in _FOLLOW_RANGES.items():
        if key not in table:
            continue
        value = _number(src, f"follow.{key}", table[key])
        if value < lo or (hi is not None and value > hi):
            bound = f">= {lo!r}" if hi is None else f"in [{lo!r}, {hi!r}]"
            raise ConfigError(f"{src}: follow.{key} = {table[key]!r} must be {bound}")
        values[key] = value
    return FollowConfig(**values)


def config_from_dict(data: dict, source: str = "<memory>") -> FigureConfig:
    """Validate a parsed TOML document; errors name source, key and value."""
    figure = data.get("figure", {})
    if not isinstance(figure, dict):
        raise ConfigError(f"{source}: [figure] must be a table")
    unknown = set(data) - {"figure", "axis", "follow"}
    if unknown:
        raise ConfigError(f"{source}: unknown top-level key(s) {sorted(unknown)} "
                          "(expected [figure], [[axis]] and optionally [follow])")
    unknown = set(figure) - {"name", "tick_period", "note"}
    if unknown:
        raise ConfigError(f"{source}: unknown key(s) {sorted(unknown)} in [figure]")
    period = _number(source, "figure.tick_period", figure.get("tick_period", DEFAULT_TICK_PERIOD),
                     positive=True)
    if period > 1.0:
        raise ConfigError(f"{source}: figure.tick_period = {period!r} s is longer than 1 s")
    tables = data.get("axis")
    if not isinstance(tables, list) or not tables:
        raise ConfigError(f"{source}: no [[axis]] tables: a figure needs at least one axis")
    axes = tuple(_axis(source, i, t) for i, t in enumerate(tables))
    seen: dict[str, int] = {}
    for i, a in enumerate(axes):
        if a.name in seen:
            raise ConfigError(f"{source}: duplicate axis name {a.name!r} "
                              f"in axis[{seen[a.name]}] and axis[{i}]")
        seen[a.name] = i
    addresses: dict[tuple[int, int], str] = {}
    for a in axes:
        key = (a.node, a.channel)
        if key in addresses:
            raise ConfigError(f"{source}: axes {addresses[key]!r} and {a.name!r} share "
                              f"node {a.node}, channel {a.channel}")
        addresses[key] = a.name
    return FigureConfig(name=str(figure.get("name", Path(source).stem)), tick_period=period,
                        axes=axes, source=source, follow=_follow(source, data.get("follow", {})))


def load_config(path: str | Path | None = None) -> FigureConfig:
    """Read and validate a figure TOML file; None gives the bundled Hoffmann 1996 figure."""
    path = Path(path) if path is not None else default_config_path()
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    return config_from_dict(data, str(path))


def default_config_path() -> Path:
    return Path(__file__).parent / "data" / "hoffmann1996.toml"
