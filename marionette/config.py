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
from dataclasses import dataclass, field, fields, make_dataclass
from pathlib import Path

from marionette import _follow
from marionette.errors import ConfigError
from marionette.textfile import read_text

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


FOLLOW_MODES = tuple(_follow.MODES)   # the C follower's modes
ON_LOST = ("flywheel", "hold")      # what the show does while the music is not followed


def _follow_config_class():
    """FollowConfig: one field per option of the C follower's table
    (MAR_FOLLOW_OPTIONS in ext/mar_follow.h, which gives its default, range
    and unit; docs/music.md lists them), and two of the show's own:
    latency None (not set: the sound card's input latency, else the
    table's default) and on_lost."""
    defaults = _follow.default_options()
    own = {"latency": (float | None, None), "on_lost": (str, "flywheel")}
    specs = []
    for name, info in _follow.OPTIONS.items():
        kind = str if name == "mode" else int if info["kind"] == "int" else float
        kind, default = own.get(name, (kind, defaults[name]))
        specs.append((name, kind, field(default=default)))
    specs.append(("on_lost", *own["on_lost"]))
    cls = make_dataclass("FollowConfig", specs, frozen=True)
    cls.__module__ = __name__
    cls.__doc__ = ("Music following (the optional [follow] table): how the playback position "
                   "follows the live music; times in s. Fields: " + ", ".join(f.name for f in fields(cls)))
    return cls


FollowConfig = _follow_config_class()


SILENT_NODE = ("stop", "hold", "estop", "continue")   # [faults] silent_node
MAX_OVERRUNS = 1_000_000


@dataclass(frozen=True)
class FaultConfig:
    """Fault reactions (the optional [faults] table, docs/formats.md).

    silent_node: what the show does when a servo node falls silent: "stop"
    (default: every axis to rest at its limits, held, latched), "hold" (the
    same, then back into the show when every node answers again), "estop"
    (as stop, and the nodes are sent ESTOP) or "continue" (play on).
    overruns: this many real-time overruns stop the show as "stop" does
    (0, the default: none do; they are counted anyway)."""

    silent_node: str = "stop"
    overruns: int = 0


@dataclass(frozen=True)
class FigureConfig:
    """A figure: its axes in order, the tick period, where it came from."""

    name: str
    tick_period: float              # [s]
    axes: tuple[AxisConfig, ...]
    source: str = "<memory>"        # file it was read from
    follow: FollowConfig = field(default_factory=FollowConfig)  # music following
    faults: FaultConfig = field(default_factory=FaultConfig)    # fault reactions

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


def follow_range(name: str) -> str:
    """A follower option's allowed range and unit from the C table, as the
    errors say it: "[lo, hi] unit"."""
    info = _follow.OPTIONS[name]
    return f"[{info['lo']:g}, {info['hi']:g}]" + (f" {info['unit']}" if info["unit"] else "")


def _follow_table(src: str, table) -> FollowConfig:
    """The optional [follow] table, checked against the C follower's table
    (kind and range of each option); defaults for what it leaves out."""
    if not isinstance(table, dict):
        raise ConfigError(f"{src}: [follow] must be a table")
    known = {f.name for f in fields(FollowConfig)}
    values = {}
    for key, value in table.items():
        info = _follow.OPTIONS.get(key)
        if key not in known:
            raise ConfigError(f"{src}: follow.{key} = {value!r} is not a known key "
                              f"(known: {', '.join(sorted(known))})")
        if key in ("mode", "on_lost"):
            names = FOLLOW_MODES if key == "mode" else ON_LOST
            if value not in names:
                raise ConfigError(f"{src}: follow.{key} = {value!r} is not known (use one of {names})")
            values[key] = value
        elif info["kind"] == "int":
            values[key] = _integer(src, f"follow.{key}", value, int(info["lo"]), int(info["hi"]))
        else:
            number = _number(src, f"follow.{key}", value)
            if not info["lo"] <= number <= info["hi"]:
                raise ConfigError(f"{src}: follow.{key} = {value!r} must be in {follow_range(key)}")
            values[key] = number
    return FollowConfig(**values)


def _faults_table(src: str, table) -> FaultConfig:
    """The optional [faults] table; defaults for what it leaves out."""
    if not isinstance(table, dict):
        raise ConfigError(f"{src}: [faults] must be a table")
    known = {f.name for f in fields(FaultConfig)}
    values = {}
    for key, value in table.items():
        if key not in known:
            raise ConfigError(f"{src}: faults.{key} = {value!r} is not a known key "
                              f"(known: {', '.join(sorted(known))})")
        if key == "silent_node":
            if value not in SILENT_NODE:
                raise ConfigError(f"{src}: faults.silent_node = {value!r} is not known "
                                  f"(use one of {SILENT_NODE})")
            values[key] = value
        else:
            values[key] = _integer(src, f"faults.{key}", value, 0, MAX_OVERRUNS)
    return FaultConfig(**values)


def config_from_dict(data: dict, source: str = "<memory>") -> FigureConfig:
    """Validate a parsed TOML document; errors name source, key and value."""
    figure = data.get("figure", {})
    if not isinstance(figure, dict):
        raise ConfigError(f"{source}: [figure] must be a table")
    unknown = set(data) - {"figure", "axis", "follow", "faults"}
    if unknown:
        raise ConfigError(f"{source}: unknown top-level key(s) {sorted(unknown)} "
                          "(expected [figure], [[axis]] and optionally [follow] and [faults])")
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
                        axes=axes, source=source, follow=_follow_table(source, data.get("follow", {})),
                        faults=_faults_table(source, data.get("faults", {})))


def load_config(path: str | Path | None = None) -> FigureConfig:
    """Read and validate a figure TOML file; None gives the bundled Hoffmann 1996 figure."""
    path = Path(path) if path is not None else default_config_path()
    try:
        data = tomllib.loads(read_text(path, ConfigError))
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    return config_from_dict(data, str(path))


def default_config_path() -> Path:
    return Path(__file__).parent / "data" / "hoffmann1996.toml"
