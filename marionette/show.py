"""Show files: the taught position of every axis every tick, and the music's
stored loudness (and, when taught from a recording, its onset strength)
every tick, with metadata. CSV (human-editable) and NPZ;
both formats are described in docs/formats.md.
"""
from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from marionette.config import UNITS, FigureConfig
from marionette.errors import ArgumentError, ShowError
from marionette.npzfile import read_npz
from marionette.textfile import read_text

CSV_MAGIC = "# marionette show 1"
MIN_COMPRESS_GAIN = 0.5         # on_limits="compress" below this gain flattens the dance: refused [1]
ONSET_COLUMN = "onset_db"       # optional CSV column after loudness: the stored onset strength [dB]
LIMIT_POLICIES = ("error", "clamp", "compress")


@dataclass
class Show:
    """A taught show: per axis one position per tick, plus the stored loudness."""

    axis_names: list[str]
    units: list[str]                 # "m" or "rad" per axis
    positions: np.ndarray            # (axes, ticks) [unit]
    loudness: np.ndarray             # (ticks,) stored music loudness, >= 0 [dimensionless]
    tick_period: float = 0.020       # [s]
    source: str = ""                 # how it was made (teach-in, generator, editor)
    music: str = ""                  # the music file it was taught to
    path: str = "<memory>"           # file it was read from, for messages
    first_line: int = 0              # CSV line of tick 0 (0: not from a CSV)
    changes: list[str] = field(default_factory=list)  # what fitting to a figure changed
    onsets: np.ndarray | None = None  # (ticks,) stored onset strength [dB], >= 0; None: not stored
    bands: np.ndarray | None = None   # (ticks, bands) stored band loudness [full scale], >= 0
                                      # (marionette/music/bands.py); None: not stored

    @property
    def n_ticks(self) -> int:
        return self.positions.shape[1]

    @property
    def duration(self) -> float:
        """Length [s]."""
        return self.n_ticks * self.tick_period

    def locate(self, tick: int) -> str:
        """Where a tick sits in the file, for messages."""
        if self.first_line:
            return f"{self.path}, line {self.first_line + tick}"
        return f"{self.path}, tick {tick}"

    def axis(self, name: str) -> np.ndarray:
        return self.positions[self.axis_names.index(name)]

    def save(self, path: str | Path) -> None:
        """Write as CSV or NPZ, by the file's suffix."""
        path = Path(path)
        if path.suffix == ".npz":
            extra = {name: value for name, value in (("onsets", self.onsets), ("bands", self.bands))
                     if value is not None}
            np.savez_compressed(path, positions=self.positions, loudness=self.loudness,
                                axis_names=np.array(self.axis_names), units=np.array(self.units),
                                tick_period=np.float64(self.tick_period),
                                source=np.array(self.source), music=np.array(self.music), **extra)
        elif path.suffix == ".csv":
            self._save_csv(path)
        else:
            raise ShowError(f"{path}: unknown show format {path.suffix!r} (use .csv or .npz)")

    def _save_csv(self, path: Path) -> None:
        with open(path, "w", newline="") as f:
            f.write(f"{CSV_MAGIC}\n# tick_period: {self.tick_period!r}\n"
                    f"# source: {self.source}\n# music: {self.music}\n"
                    f"# units: {','.join(self.units)}\n")
            w = csv.writer(f, lineterminator="\n")
            onset = [] if self.onsets is None else [ONSET_COLUMN]
            w.writerow(["tick", "loudness", *onset, *self.axis_names])
            for k in range(self.n_ticks):
                onset = [] if self.onsets is None else [repr(float(self.onsets[k]))]
                w.writerow([k, repr(float(self.loudness[k])), *onset,
                            *(repr(float(v)) for v in self.positions[:, k])])


def _parse_float(path, line_no, column, text) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ShowError(f"{path}, line {line_no}, column {column!r}: "
                        f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise ShowError(f"{path}, line {line_no}, column {column!r}: value {text!r} is not finite")
    return value


def _read_csv(path: Path) -> Show:
    meta: dict[str, str] = {}
    header: list[str] | None = None
    rows: list[list[float]] = []
    first_line = 0
    for line_no, line in enumerate(io.StringIO(read_text(path, ShowError), newline=""), start=1):
        text = line.strip()
        if not text:
            continue
        if text.startswith("#"):
            if line_no == 1 and text != CSV_MAGIC:
                raise ShowError(f"{path}, line 1: expected {CSV_MAGIC!r}, found {text!r}")
            if ":" in text and header is None:
                key, _, value = text[1:].partition(":")
                meta[key.strip()] = value.strip()
            continue
        cells = next(csv.reader([text]))
        if header is None:
            if line_no == 1:
                raise ShowError(f"{path}, line 1: expected {CSV_MAGIC!r}")
            header = [c.strip() for c in cells]
            with_onsets = len(header) > 2 and header[2] == ONSET_COLUMN
            if header[:2] != ["tick", "loudness"] or len(header) < 3 + with_onsets:
                raise ShowError(f"{path}, line {line_no}: header must be "
                                f"'tick,loudness,[{ONSET_COLUMN},]<axis>,...', found {text!r}")
            dup = {h for h in header if header.count(h) > 1}
            if dup:
                raise ShowError(f"{path}, line {line_no}: duplicate column(s) {sorted(dup)}")
            continue
        if len(cells) != len(header):
            raise ShowError(f"{path}, line {line_no}: {len(cells)} values, "
                            f"the header has {len(header)} columns")
        tick = cells[0].strip()
        if tick != str(len(rows)):
            raise ShowError(f"{path}, line {line_no}: tick {tick!r}, expected {len(rows)} "
                            "(ticks must count up from 0 without gaps)")
        if not rows:
            first_line = line_no
        rows.append([_parse_float(path, line_no, header[i], c) for i, c in enumerate(cells[1:], 1)])
    if header is None or not rows:
        raise ShowError(f"{path}: no data rows")
    data = np.array(rows, dtype=np.float64)
    first_axis = 3 if header[2] == ONSET_COLUMN else 2       # [column]
    names = header[first_axis:]
    try:
        period = float(meta.get("tick_period", "0.02"))
    except ValueError:
        raise ShowError(f"{path}: tick_period {meta['tick_period']!r} is not a number") from None
    units = [u.strip() for u in meta["units"].split(",")] if "units" in meta else ["m"] * len(names)
    return Show(axis_names=names, units=units, positions=data[:, first_axis - 1:].T.copy(),
                loudness=data[:, 0].copy(), tick_period=period,
                source=meta.get("source", ""), music=meta.get("music", ""),
                path=str(path), first_line=first_line,
                onsets=data[:, 1].copy() if first_axis == 3 else None)


def _read_npz(path: Path) -> Show:
    z = read_npz(path, ShowError)
    missing = {"positions", "loudness", "axis_names"} - set(z)
    if missing:
        raise ShowError(f"{path}: missing array(s) {sorted(missing)}")

    def numbers(name):
        try:
            return np.array(z[name], dtype=np.float64)
        except (TypeError, ValueError):
            raise ShowError(f"{path}: array {name!r} ({z[name].dtype}) is not numbers") from None

    def text(name, default=""):
        return str(z[name]) if name in z else default

    names = [str(n) for n in np.atleast_1d(z["axis_names"])]
    units = [str(u) for u in np.atleast_1d(z["units"])] if "units" in z else ["m"] * len(names)
    period = numbers("tick_period") if "tick_period" in z else np.float64(0.02)
    if period.size != 1:
        raise ShowError(f"{path}: tick_period has {period.size} values, expected one")
    return Show(axis_names=names, units=units, positions=numbers("positions"),
                loudness=numbers("loudness"), tick_period=float(period.reshape(())),
                source=text("source"), music=text("music"), path=str(path),
                onsets=numbers("onsets") if "onsets" in z else None,
                bands=numbers("bands") if "bands" in z else None)


def validate(show: Show) -> None:
    """Shape, names, units and finiteness; errors name file, place, axis and value."""
    p = show.positions
    if p.ndim != 2 or p.shape[0] != len(show.axis_names) or p.shape[1] == 0:
        raise ShowError(f"{show.path}: positions have shape {p.shape}, expected "
                        f"({len(show.axis_names)} axes, ticks > 0)")
    if show.loudness.shape != (p.shape[1],):
        raise ShowError(f"{show.path}: loudness has shape {show.loudness.shape}, "
                        f"expected ({p.shape[1]},)")
    if len(show.units) != len(show.axis_names):
        raise ShowError(f"{show.path}: {len(show.units)} units ({', '.join(show.units)}) for "
                        f"{len(show.axis_names)} axes ({', '.join(show.axis_names)}): a column "
                        "missing, or a unit too many?")
    for name, unit in zip(show.axis_names, show.units):
        if unit not in UNITS:
            raise ShowError(f"{show.path}: axis {name!r} has unknown unit {unit!r} (use one of {UNITS})")
    if not (math.isfinite(show.tick_period) and show.tick_period > 0):
        raise ShowError(f"{show.path}: tick_period {show.tick_period!r} must be a positive number")
    bad = np.argwhere(~np.isfinite(p))
    if bad.size:
        j, k = bad[0]
        raise ShowError(f"{show.locate(k)}: axis {show.axis_names[j]!r} has value {float(p[j, k])!r}")
    bad = np.flatnonzero(~(show.loudness >= 0))
    if bad.size:
        k = bad[0]
        raise ShowError(f"{show.locate(k)}: loudness {float(show.loudness[k])!r} must be finite and >= 0")
    if show.onsets is not None:
        if show.onsets.shape != (p.shape[1],):
            raise ShowError(f"{show.path}: {ONSET_COLUMN} has shape {show.onsets.shape}, "
                            f"expected ({p.shape[1]},)")
        bad = np.flatnonzero(~(np.isfinite(show.onsets) & (show.onsets >= 0)))
        if bad.size:
            k = bad[0]
            raise ShowError(f"{show.locate(k)}: {ONSET_COLUMN} {float(show.onsets[k])!r} "
                            "must be finite and >= 0")
    if show.bands is not None:
        b = show.bands
        if b.ndim != 2 or b.shape[0] != p.shape[1] or not 1 <= b.shape[1] <= 32:
            raise ShowError(f"{show.path}: bands have shape {b.shape}, expected ({p.shape[1]} ticks, 1 to 32 bands)")
        bad = np.argwhere(~(np.isfinite(b) & (b >= 0)))
        if bad.size:
            k, j = bad[0]
            raise ShowError(f"{show.locate(k)}: band {j} loudness {float(b[k, j])!r} must be finite and >= 0")


def check_axes(show: Show, config: FigureConfig) -> None:
    """The show has a trajectory for every axis of the figure, and no other."""
    figure_names = config.axis_names
    unknown = [n for n in show.axis_names if n not in figure_names]
    if unknown:
        raise ShowError(f"{show.path}: unknown axis {unknown[0]!r} (not in {config.source}; "
                        f"known: {', '.join(figure_names)})")
    missing = [n for n in figure_names if n not in show.axis_names]
    if missing:
        raise ShowError(f"{show.path}: no trajectory (column) for axis {missing[0]!r} of "
                        f"{config.source}")


def fit_to_figure(show: Show, config: FigureConfig, on_limits: str = "error") -> Show:
    """The show with its axes in the figure's order, checked against the figure.

    on_limits: "error" (default) refuses a position outside an axis's limits;
    "clamp" cuts such positions to the limit; "compress" scales the axis's
    whole trajectory affinely into the limits. Every change is listed in
    the returned show's ``changes``.
    """
    if on_limits not in LIMIT_POLICIES:
        raise ArgumentError(f"on_limits must be one of {LIMIT_POLICIES}, not {on_limits!r}")
    if not math.isclose(show.tick_period, config.tick_period, rel_tol=1e-9):
        raise ShowError(f"{show.path}: tick_period {show.tick_period!r} s does not match "
                        f"{config.source}: {config.tick_period!r} s")
    check_axes(show, config)
    figure_names = config.axis_names
    row_of = {name: j for j, name in enumerate(show.axis_names)}
    order = [row_of[n] for n in figure_names]
    positions = show.positions[order].copy()
    changes = list(show.changes)
    for j, axis in enumerate(config.axes):
        unit = show.units[order[j]]
        if unit != axis.unit:
            raise ShowError(f"{show.path}: axis {axis.name!r} is in {unit!r}, "
                            f"{config.source} says {axis.unit!r}")
        x = positions[j]
        outside = np.flatnonzero((x < axis.min) | (x > axis.max))
        if not outside.size:
            continue
        k = outside[0]
        if on_limits == "error":
            raise ShowError(f"{show.locate(k)}: axis {axis.name!r} position {float(x[k])!r} {axis.unit} is "
                            f"outside its limits [{axis.min!r}, {axis.max!r}] "
                            f"({outside.size} ticks outside; on_limits='clamp' or 'compress' fits it)")
        if on_limits == "clamp":
            worst = float(np.max(np.maximum(x - axis.max, axis.min - x)))
            positions[j] = np.clip(x, axis.min, axis.max)
            changes.append(f"axis {axis.name!r}: clamped {outside.size} ticks into "
                           f"[{axis.min!r}, {axis.max!r}] {axis.unit}, by up to {worst:.6g} {axis.unit}")
        else:
            lo, hi = min(float(x.min()), axis.min), max(float(x.max()), axis.max)
            gain = (axis.max - axis.min) / (hi - lo)
            if gain < MIN_COMPRESS_GAIN:
                k = int(np.argmax(np.maximum(x - axis.max, axis.min - x)))      # farthest out
                raise ShowError(f"{show.locate(k)}: axis {axis.name!r} position {float(x[k])!r} "
                                f"{axis.unit} would compress the axis's range [{lo:.6g}, {hi:.6g}] "
                                f"into [{axis.min!r}, {axis.max!r}] by a gain of {gain:.3g}, under "
                                f"{MIN_COMPRESS_GAIN:g}: the dance would be flattened (an outlier? "
                                "on_limits='clamp' cuts it instead)")
            positions[j] = np.clip(axis.min + (x - lo) * gain, axis.min, axis.max)
            changes.append(f"axis {axis.name!r}: compressed range [{lo:.6g}, {hi:.6g}] into "
                           f"[{axis.min!r}, {axis.max!r}] {axis.unit} (gain {gain:.6g})")
    return replace(show, axis_names=list(figure_names),
                   units=[a.unit for a in config.axes], positions=positions, changes=changes)


def load_show(path: str | Path, config: FigureConfig | None = None,
              on_limits: str = "error") -> Show:
    """Read a .csv or .npz show; with a figure, check and order it for that figure."""
    path = Path(path)
    if not path.exists():
        raise ShowError(f"{path}: no such file")
    if path.suffix == ".csv":
        show = _read_csv(path)
    elif path.suffix == ".npz":
        show = _read_npz(path)
    else:
        raise ShowError(f"{path}: unknown show format {path.suffix!r} (use .csv or .npz)")
    if config is not None:          # a missing column named before the counts disagree
        check_axes(show, config)
    validate(show)
    return fit_to_figure(show, config, on_limits) if config is not None else show
