"""Music following from Python: the C follower (ext/mar_follow.c) over a
stored loudness, fed live loudness frames one per tick.

    from marionette.music.follower import Follower
    f = Follower(show.loudness, config.follow, period=config.tick_period)
    track = f.run(live_frames)          # arrays, one entry per tick
    out = f.step(frame)                 # one tick (NaN: no frame this tick)

Positions are in stored ticks (show ticks): ``position * period`` is the
taught music time [s] that the live music has reached at that tick. Rates
are stored ticks per tick (1.0: the live music plays as fast as taught).
docs/music.md describes the algorithm and the options.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from marionette import _follow
from marionette.config import FollowConfig, follow_range
from marionette.errors import MarionetteError

STATES = _follow.STATES         # state code -> name: searching, locked, holding, paused, waiting
FLAGS = _follow.FLAGS           # flag name -> bit
OPTIONS = _follow.OPTIONS       # option name -> kind, default, lo, hi, unit, why (ext/mar_follow.h)
MAX_BANDS = _follow.MAX_BANDS   # band levels per frame, at most (MAR_FOLLOW_MAX_BANDS)
DEFAULT_START = 0.0             # where the live music starts by default [s of the show]: the top (a cue)


class FollowError(MarionetteError, ValueError):
    """The follower refused its options or the stored loudness."""


@dataclass(frozen=True)
class FollowOut:
    """One tick's answer."""

    position: float             # [stored ticks]
    rate: float                 # [stored ticks per tick]
    confidence: float           # [0, 1]
    state: str                  # one of STATES
    flags: int                  # FLAGS bits


@dataclass
class Track:
    """A run of ticks: one entry per tick."""

    position: np.ndarray        # [stored ticks]
    rate: np.ndarray            # [stored ticks per tick]
    confidence: np.ndarray      # [0, 1]
    state: np.ndarray           # int8 state codes (index into STATES)
    flags: np.ndarray           # uint32 FLAGS bits
    ns: np.ndarray | None = None  # wall time of each C step [ns], when timed


def c_options(settings: FollowConfig | None = None, period: float = 0.020, **overrides) -> dict:
    """The C follower's options (the names and units of its table,
    OPTIONS) for figure settings at tick period [s]; overrides name
    options directly. latency None (not set) is the table's default."""
    s = settings or FollowConfig()
    if not period > 0:
        raise FollowError(f"tick period {period!r} s must be > 0")
    opt = {name: getattr(s, name) for name in OPTIONS}
    if opt["latency"] is None:
        opt["latency"] = OPTIONS["latency"]["default"]
    opt.update(overrides, tick_period=period)
    return opt


def options_markdown() -> str:
    """The table of options in docs/music.md, made from the C table (the
    docs keep a copy; tests/test_follow.py checks that it is this)."""
    rows = ["| key | default | allowed | unit | what |", "|---|---|---|---|---|"]
    for name, info in OPTIONS.items():
        if name == "mode":
            names = {code: f'"{mode}"' for mode, code in _follow.MODES.items()}
            default, allowed = names[int(info["default"])], ", ".join(names.values())
        else:
            allowed = f"{info['lo']:g} .. {info['hi']:g}"
            default = f"{info['default']:g}"
        rows.append(f"| `{name}` | {default} | {allowed} | {info['unit']} | {info['why']} |")
    return "\n".join(rows) + "\n"


def cue_ticks(start: float | None, n_stored: int, period: float, what: str = "start") -> float:
    """A start [s into the taught music] as a cue [stored ticks]; None:
    unknown (NaN). what names the setting in the error."""
    if start is None:
        return float("nan")
    start = float(start)
    if not (math.isfinite(start) and 0.0 <= start <= n_stored * period):
        raise FollowError(f"{what} {start!r} s is outside the taught music [0, {n_stored * period:g}] s "
                          f"(unknown: None)")
    return start / period


class Follower:
    """The C follower over stored (linear loudness, one value per tick, >= 0).

    onset: the stored onset strength (marionette.music.feature.onsets, [dB], one
    per tick, >= 0) or None. With it the tracker places its correlation
    peak on the loudness plus onset_weight times the onset, which a room's
    colouring does not shift, wherever the live frames bring onsets too
    (NaN: a frame without; the loudness alone where a window has none).
    bands: the stored band levels (marionette.music.bands, (ticks, n_bands)
    [full scale], >= 0) or None. With them the correlations run jointly on
    the bands wherever the live frames bring as many (smooth mode); frames
    without (a one-band node) are followed on the loudness. settings: a FollowConfig (the figure's [follow] table) or None for the
    defaults; period: tick period [s]; options: options by name (OPTIONS,
    in their units: times in s), which override the settings.
    """

    def __init__(self, stored, settings: FollowConfig | None = None, period: float = 0.020,
                 onset=None, bands=None, **options):
        stored = np.asarray(stored, dtype=np.float64)
        if stored.ndim != 1 or len(stored) < 2:
            raise FollowError(f"stored loudness must be a 1-d array of at least 2 values, "
                              f"got shape {stored.shape}")
        bad = np.flatnonzero(~(np.isfinite(stored) & (stored >= 0)))
        if len(bad):
            raise FollowError(f"stored loudness[{bad[0]}] = {float(stored[bad[0]])!r} must be finite and >= 0")
        if onset is not None:
            onset = np.asarray(onset, dtype=np.float64)
            if onset.shape != stored.shape:
                raise FollowError(f"stored onsets: shape {onset.shape}, the loudness has {stored.shape}")
            bad = np.flatnonzero(~(np.isfinite(onset) & (onset >= 0)))
            if len(bad):
                raise FollowError(f"stored onset[{bad[0]}] = {float(onset[bad[0]])!r} must be finite and >= 0")
        if bands is not None:
            bands = stored_bands(bands, len(stored))
        opt = c_options(settings, period, **options)
        problem = options_problem(opt)
        if problem:
            raise FollowError(f"follower options: {problem}")
        self._f = _follow.Follower(stored, opt, onset, bands)
        self.period = float(period)             # [s]
        self.options = dict(self._f.options)

    @property
    def stored_length(self) -> int:
        """Stored frames [ticks]."""
        return self._f.stored_length

    @property
    def n_bands(self) -> int:
        """Stored band levels per tick (0: none)."""
        return self._f.n_bands

    def step(self, live: float = float("nan"), onset: float = float("nan"), bands=None) -> FollowOut:
        """One tick of the show's clock, as the engine runs it
        (mar_follow_tick), with the live frame that came in it (linear
        loudness, its onset strength [dB] when made with onsets, its band
        levels [full scale] or None; NaN: none came)."""
        p, r, c, s, fl = self._f.step(float(live), float(onset), bands)
        return FollowOut(position=p, rate=r, confidence=c, state=STATES[s], flags=fl)

    def run(self, live, onset=None, timing: bool = False, bands=None) -> Track:
        """One tick per live frame (NaN: no frame that tick), in C without the
        GIL; onset: the live onset strengths [dB], one per frame, when made
        with onsets; bands: the live band levels (frames, n_bands) [full
        scale] or None."""
        live = np.asarray(live, dtype=np.float64)
        if live.ndim != 1:
            raise FollowError(f"live frames must be a 1-d array, got shape {live.shape}")
        if onset is not None and np.shape(onset) != live.shape:
            raise FollowError(f"live onsets: shape {np.shape(onset)}, the live frames have {live.shape}")
        if bands is not None:
            bands = np.asarray(bands, dtype=np.float64)
            if bands.ndim != 2 or len(bands) != len(live) or bands.shape[1] > MAX_BANDS:
                raise FollowError(f"live bands: shape {bands.shape}, the live frames have {live.shape} "
                                  f"(at most {MAX_BANDS} bands)")
        out = self._f.run(live, onset, bands, timing)
        return Track(position=out["position"], rate=out["rate"], confidence=out["confidence"],
                     state=out["state"], flags=out["flags"], ns=out.get("ns"))

    def reset(self, position: float | None = None) -> None:
        """The live music is at position [stored ticks] now (a known start or
        a seek); None: unknown, search the whole piece."""
        self._f.reset(float("nan") if position is None else float(position))

    def cue(self, position: float | None = 0.0) -> None:
        """The live music will start at position [stored ticks] (a cue): wait
        there for its onset, then play from it (mar_follow_cue); None:
        unknown, search the whole piece."""
        self._f.cue(float("nan") if position is None else float(position))

    def counters(self) -> dict:
        """steps, frames, missing, bad_input, measurements, rejected, locks,
        pauses, resumes, search_steps."""
        return self._f.counters()


def stored_bands(bands, n_ticks: int, what: str = "stored bands") -> np.ndarray:
    """Band levels (n_ticks, n_bands) [full scale] as the follower takes
    them, else FollowError naming the first bad value."""
    bands = np.asarray(bands, dtype=np.float64)
    if bands.ndim != 2 or len(bands) != n_ticks or not 1 <= bands.shape[1] <= MAX_BANDS:
        raise FollowError(f"{what}: shape {bands.shape}, expected ({n_ticks}, 1 .. {MAX_BANDS})")
    bad = np.argwhere(~(np.isfinite(bands) & (bands >= 0)))
    if len(bad):
        i, b = bad[0]
        raise FollowError(f"{what}[{i}, {b}] = {float(bands[i, b])!r} must be finite and >= 0")
    return bands


def sync_ticks(live_frames) -> np.ndarray:
    """Live frames laid on the tick grid the way the engine sees them: tick
    k has heard the live audio up to k * T, so it gets frame k - 1, and tick
    0 gets none (NaN). Length len(live_frames) + 1; rows of band levels
    (frames, n_bands) get a row of NaN in front."""
    live_frames = np.asarray(live_frames, dtype=np.float64)
    return np.concatenate([np.full((1,) + live_frames.shape[1:], np.nan), live_frames])


def engine_options(config, show, mode: str | bool = True) -> bytes:
    """The C options of the follower the engine runs in its tick, for a
    figure (its [follow] table) and a show (whose stored loudness it follows).
    mode: "smooth", "paper", or True for the figure's own."""
    stored = np.asarray(show.loudness, dtype=np.float64)
    bad = np.flatnonzero(~(np.isfinite(stored) & (stored >= 0)))
    if len(stored) < 2 or len(bad):
        raise FollowError(f"{show.path}: following the music needs the show's stored loudness, "
                          f"finite and >= 0 at every tick"
                          + (f"; tick {bad[0]} has {float(stored[bad[0]])!r}" if len(bad) else ""))
    if not np.any(stored > 0):
        raise FollowError(f"{show.path}: the stored loudness is silent throughout; nothing to follow")
    overrides = {} if mode is True else {"mode": mode}
    opt = c_options(config.follow, config.tick_period, **overrides)
    problem = options_problem(opt)
    if problem:
        raise FollowError(f"{config.source}: [follow]: {problem}")
    return _follow.options_bytes(opt)


def options_problem(opt: dict) -> str | None:
    """What the C follower refuses in opt (c_options' dict), in words; None
    when it takes them."""
    try:
        problem = _follow.options_problem(opt)
    except KeyError as exc:
        return f"unknown option {exc.args[0]!r} (known: {', '.join(sorted(OPTIONS))})"
    except ValueError as exc:
        return f"{exc.args[0]} = {opt.get(exc.args[0])!r} is not a value of its kind"
    name = (problem or "").split(" ")[0]
    if name in OPTIONS and problem.endswith("outside its range"):
        return f"{name} = {opt[name]!r} must be in {follow_range(name)}"
    return problem
