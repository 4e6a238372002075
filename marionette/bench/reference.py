"""A pure-numpy reference of the tick the C engine computes, vectorised over axes.

For benchmarks and tests only: the engine never runs this code (DESIGN.md,
"one implementation of each algorithm"). It mirrors, operation for
operation and in the same order, so that it agrees bit for bit:

- ext/mar_sample.c  ``mar_sample``: linear or Catmull-Rom cubic sampling of a
  trajectory at a fractional position, with the mirrored neighbour at the
  ends and the end values held (zero slope) outside [0, n-1];
- ext/mar_limits.c  ``mar_brake_speed`` and ``mar_limit_step``: velocity,
  acceleration and braking bounds, non-finite targets refused, final clamp;
- ext/mar_engine.c  ``mar_engine_tick``: playback position p [show ticks]
  advancing by the rate r [show ticks per tick] each tick, held at the last
  show tick; each axis sampled at p + r*lead/T [show ticks], with lead [s] =
  dead time (+ time constant in "mean_delay" mode), and in
  "dead_time_lag" mode the lag feed-forward target = x + tau*slope*r/T [unit];
  the command before the first tick is the show's first pose, at rest.

Usage::

    ref = ReferenceEngine(config, show, lead="dead_time_lag", interpolation="cubic")
    commands = ref.step(100)        # (100, axes) commands [unit]
"""
from __future__ import annotations

import numpy as np

from marionette.config import FigureConfig
from marionette.errors import ArgumentError
from marionette.show import Show, fit_to_figure

LEADS = ("dead_time_lag", "mean_delay", "none")
INTERPOLATIONS = ("cubic", "linear")


def sample(x: np.ndarray, p: np.ndarray, interpolation: str = "cubic") -> tuple[np.ndarray, np.ndarray]:
    """Each row of x (axes, n) [unit] at its own position p[j] [show ticks].

    Returns (value [unit], slope [unit/show tick]) per row, as ext/mar_sample.c:
    p <= 0 (or NaN) holds x[:, 0], p >= n-1 holds x[:, n-1], both with zero slope.
    """
    n_axes, n = x.shape
    p = np.asarray(p, dtype=np.float64)
    if n == 1:
        return x[:, 0].copy(), np.zeros(n_axes)
    last = float(n - 1)
    low = ~(p > 0.0)                          # also catches NaN p
    high = p >= last
    inside = ~(low | high)
    pc = np.where(inside, p, 0.0)
    i = pc.astype(np.intp)                    # segment [i, i+1]; pc >= 0 so this is floor
    f = pc - i                                # fraction in the segment [1]
    flat = x.ravel()
    base = np.arange(n_axes, dtype=np.intp) * n + i
    x1 = flat[base]
    x2 = flat[base + 1]
    with np.errstate(over="ignore", invalid="ignore"):
        if interpolation == "linear":
            slope = x2 - x1
            value = x1 + f * (x2 - x1)
        else:
            # Catmull-Rom tangents; at the ends the missing neighbour is mirrored
            x0 = np.where(i > 0, flat.take(base - 1, mode="clip"), 2.0 * x1 - x2)
            x3 = np.where(i + 2 < n, flat.take(base + 2, mode="clip"), 2.0 * x2 - x1)
            m1 = 0.5 * (x2 - x0)
            m2 = 0.5 * (x3 - x1)
            d = x2 - x1
            b = 3.0 * d - 2.0 * m1 - m2
            c = m1 + m2 - 2.0 * d
            slope = m1 + f * (2.0 * b + 3.0 * f * c)
            value = x1 + f * (m1 + f * (b + f * c))
    value = np.where(low, x[:, 0], np.where(high, x[:, n - 1], value))
    slope = np.where(inside, slope, 0.0)
    return value, slope


def brake_speed(distance: np.ndarray, max_accel: np.ndarray, period: float) -> np.ndarray:
    """Highest speed [unit/s] that can still stop within distance [unit] at
    max_accel [unit/s^2], after one more tick of period [s] at that speed."""
    aT = max_accel * period
    with np.errstate(over="ignore", invalid="ignore"):
        v = -aT + np.sqrt(aT * aT + 2.0 * max_accel * distance)   # NaN where distance < 0 ...
    return np.where(distance <= 0.0, 0.0, v)                      # ... replaced here, as in C


def limit_step(pos_min, pos_max, max_speed, max_accel, period: float,
               x0: np.ndarray, v0: np.ndarray, target: np.ndarray):
    """Next commands [unit] from x0 [unit] moving at v0 [unit/s] towards target [unit].

    Limits per axis: pos_min, pos_max [unit], max_speed [unit/s], max_accel
    [unit/s^2]; period [s]. Returns (x1 [unit], v1 [unit/s], limited [bool]),
    as ext/mar_limits.c mar_limit_step.
    """
    with np.errstate(over="ignore", invalid="ignore"):   # huge limits may overflow, as in C
        T = period
        aT = max_accel * T
        hi = max_speed
        lo = -max_speed
        hi = np.where(v0 + aT < hi, v0 + aT, hi)
        lo = np.where(v0 - aT > lo, v0 - aT, lo)
        up = brake_speed(pos_max - x0, max_accel, T)
        down = brake_speed(x0 - pos_min, max_accel, T)
        hi = np.where(up < hi, up, hi)
        lo = np.where(-down > lo, -down, lo)
        # a non-finite target is never followed: slow down to rest instead
        finite = np.isfinite(target)
        want = np.where(finite, (target - x0) / T, 0.0)      # [unit/s]
        v = np.where(want > hi, hi, want)
        v = np.where(v < lo, lo, v)                           # lo wins should rounding cross
        # an unlimited step lands exactly on the target, bit for bit
        x1 = np.where(finite & (v == want), target, x0 + v * T)
        x1 = np.where(x1 > pos_max, pos_max, x1)              # absorbs rounding only
        x1 = np.where(x1 < pos_min, pos_min, x1)
        limited = ~finite | (x1 != target)
        v1 = (x1 - x0) / T
    return x1, v1, limited


class ReferenceEngine:
    """The C engine's step mode in numpy: same inputs, same commands.

    lead: "dead_time_lag", "mean_delay" or "none"; interpolation: "cubic" or
    "linear"; rate [show ticks per tick]. The show is fitted to the figure
    as marionette.Engine does (same axis order, same on_limits policy),
    unless fitted=True says it already is (e.g. an Engine's ``.show``).
    """

    def __init__(self, config: FigureConfig, show: Show, *, lead: str = "dead_time_lag",
                 interpolation: str = "cubic", rate: float = 1.0, on_limits: str = "error",
                 fitted: bool = False):
        if lead not in LEADS:
            raise ArgumentError(f"lead must be one of {LEADS}, not {lead!r}")
        if interpolation not in INTERPOLATIONS:
            raise ArgumentError(f"interpolation must be one of {INTERPOLATIONS}, not {interpolation!r}")
        if not fitted:
            show = fit_to_figure(show, config, on_limits)
        if show.positions.shape[0] != len(config.axes):
            raise ArgumentError(f"the show has {show.positions.shape[0]} axes, "
                                f"the figure {len(config.axes)}")
        axes = config.axes
        self.period = float(config.tick_period)                              # T [s]
        self.interpolation = interpolation
        self.positions = np.ascontiguousarray(show.positions, dtype=np.float64)  # (axes, ticks) [unit]
        self.loudness = np.ascontiguousarray(show.loudness, dtype=np.float64)[None, :]
        self.n_axes, self.n_ticks = self.positions.shape
        self.pos_min = np.array([a.min for a in axes], dtype=np.float64)      # [unit]
        self.pos_max = np.array([a.max for a in axes], dtype=np.float64)      # [unit]
        self.max_speed = np.array([a.max_speed for a in axes], dtype=np.float64)  # [unit/s]
        self.max_accel = np.array([a.max_accel for a in axes], dtype=np.float64)  # [unit/s^2]
        dead = np.array([a.dead_time for a in axes], dtype=np.float64)        # [s]
        tau = np.array([a.time_constant for a in axes], dtype=np.float64)     # [s]
        if lead == "none":
            self.lead_s = np.zeros(self.n_axes)                               # [s]
        elif lead == "mean_delay":
            self.lead_s = dead + tau
        else:
            self.lead_s = dead.copy()
        self.feed_forward = tau.copy() if lead == "dead_time_lag" else np.zeros(self.n_axes)  # [s]
        self.command = self.positions[:, 0].copy()       # [unit], the first pose
        self.velocity = np.zeros(self.n_axes)            # [unit/s], at rest
        self.limited = np.zeros(self.n_axes, dtype=bool)  # last tick's limited axes
        self.position = 0.0                              # p [show ticks]
        self.rate = 1.0                                  # r [show ticks per tick]
        self.stored_loudness = float("nan")              # taught loudness at p
        self.end = False                                 # p reached the last show tick
        self.tick_count = 0                              # ticks run
        self._rate_request = 1.0
        self._seek_request: float | None = None
        self.set_rate(rate)

    def set_rate(self, rate: float) -> None:
        """Playback rate [show ticks per tick], in force from the next tick."""
        self._rate_request = float(rate)

    def seek(self, position: float) -> None:
        """Jump the playback position [show ticks] at the next tick."""
        self._seek_request = float(position)

    def tick(self) -> np.ndarray:
        """One tick; returns the commands [unit] (the engine's own array, not a copy)."""
        T = self.period
        last = float(self.n_ticks - 1)
        if self.tick_count > 0:
            self.position += self.rate * 1.0             # one period elapsed
        self.rate = self._rate_request
        if self._seek_request is not None:
            self.position = self._seek_request
            self._seek_request = None
        if self.position < 0.0:
            self.position = 0.0
        self.end = self.position >= last
        if self.end:
            self.position = last
        p, r = self.position, self.rate
        ahead = p + r * self.lead_s / T                  # [show ticks]
        x, slope = sample(self.positions, ahead, self.interpolation)
        with np.errstate(over="ignore", invalid="ignore"):
            target = x + self.feed_forward * slope * r / T  # [unit]
        self.command, self.velocity, self.limited = limit_step(
            self.pos_min, self.pos_max, self.max_speed, self.max_accel, T,
            self.command, self.velocity, target)
        self.stored_loudness = float(sample(self.loudness, np.array([p]), "linear")[0][0])
        self.tick_count += 1
        return self.command

    def step(self, n: int = 1) -> np.ndarray:
        """n ticks; their commands [unit] as an (n, axes) array."""
        out = np.empty((n, self.n_axes))
        for k in range(n):
            out[k] = self.tick()
        return out
