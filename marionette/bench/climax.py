"""``climax``: do the shaped points of rest land on time on the servos? [ticks]

1. A random taught dance for the figure (fixed seed): per axis, climaxes at
   random intervals (0.6 .. 2.0 s) with random values in the middle 80 % of
   the position range, joined by raised-cosine moves whose peak speed may
   exceed the servo's top speed (the dancer is faster than the machinery),
   plus small wiggles (0.4 % of the range, below the prominence) that must
   not count as points of rest.
2. Shaped by ``marionette.shape.shape_show`` (policy reduce, default
   prominence, ``rest_tolerance=0``: no holds, so every climax is a single
   extremum of the shaped trajectory, not a plateau), once per
   lead below: planned for the command the engine makes with that lead
   (docs/shaping.md), so its limiter stays idle (``limited_axis_ticks_*``
   counts where it did act).
3. Played through ``Engine(config, shaped, lead=..., record=True).step(n)``
   with ``lead="dead_time_lag"`` (compensated) and ``lead="none"``.
4. Each axis's commands go into a simulated servo: zero-order hold of each
   tick's command, dead time ``axis.dead_time - period/2`` (the figure's dead
   time includes the half tick the hold adds, as identification from
   setpoints measures it; tests/test_engine.py ``servo_response``), then a
   first-order lag ``axis.time_constant``, on a fine internal step of
   period/SUBSTEPS (exact discretisation of the lag).
5. For every climax (an interior extremum of the shaped trajectory) the
   timing error [ticks] is the time of the servo's extremum of the same kind
   nearest the climax tick (between the neighbouring climaxes, refined by a
   parabola), less the climax tick: where the servo's motion turns, as the
   issue measures it. The shaper makes a climax where the figure turns the
   vertex of a parabola (the moves on either side share their acceleration
   there, docs/shaping.md "Turns"), so that extremum is sharp; a climax
   where they share none would stay flat, at rest with no acceleration, its
   extremum where micrometre errors put it (``turning`` counts the others).
   Beside it, ``alignment_*``: the shift, on the fine grid and refined by a
   parabola, that best aligns the servo's motion with the shaped
   trajectory's (evaluated exactly from its moves) over the ticks within
   ALIGN_TICKS of the climax (and no nearer a neighbouring climax than
   half-way): it times a flat climax too.
   A climax whose excursion was reduced so far that it is no longer an
   extremum of the shaped trajectory is not timed (climaxes counts the rest).

Target: max |error| <= 1 tick with compensation. JSON keys:
climax_error_ticks_max_compensated, climax_error_ticks_median_compensated,
climax_error_ticks_max_uncompensated, climax_error_ticks_median_uncompensated,
alignment_error_ticks_max_* and _median_* (both leads), turning (climaxes
that turn, of climaxes),
limited_axis_ticks_compensated, limited_axis_ticks_uncompensated, plus
climaxes, infeasible (of the compensated shaping), seconds, seed,
target_ticks, target_met.
"""
from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from marionette import _shape
from marionette.config import FigureConfig, load_config
from marionette.engine import Engine
from marionette.shape import shape_show
from marionette.show import Show

SEED = 1996
SECONDS = 30.0        # length of the random dance [s]
SUBSTEPS = 20         # fine simulation steps per tick [1]
TARGET_TICKS = 1.0    # max |climax timing error| with compensation [ticks]
ALIGN_TICKS = 5       # the motion within this many ticks of a climax is aligned [ticks]
MAX_SHIFT_TICKS = 40  # shifts tried [ticks], either way


def random_dance(config: FigureConfig, seconds: float = SECONDS, seed: int = SEED) -> Show:
    """A taught dance with sharp climaxes, sometimes faster than the servos."""
    rng = np.random.default_rng(seed)
    T = config.tick_period
    n = int(round(seconds / T))
    t = np.arange(n) * T                                              # [s]
    positions = np.empty((len(config.axes), n))
    for j, a in enumerate(config.axes):
        span = a.max - a.min                                          # [unit]
        mid = 0.5 * (a.min + a.max)
        times = [0.0, 1.0]                                            # 1 s at rest first
        while times[-1] < seconds:
            times.append(times[-1] + rng.uniform(0.6, 2.0))
        values = mid + rng.uniform(-0.4, 0.4, len(times)) * span
        values[:2] = mid
        x = np.interp(t, times, values)                               # knots, then ...
        k = np.searchsorted(times, t, side="right") - 1
        t0, t1 = np.asarray(times)[k], np.asarray(times)[k + 1]
        s = (t - t0) / (t1 - t0)                                      # [1]
        x = values[k] + (values[k + 1] - values[k]) * 0.5 * (1 - np.cos(np.pi * s))   # raised cosine
        wiggle = 0.004 * span * np.sin(2 * np.pi * rng.uniform(1.5, 3.0) * t + rng.uniform(0, 6.3))
        positions[j] = np.clip(x + wiggle * np.clip(t - 1.0, 0.0, 1.0), a.min, a.max)
    return Show(axis_names=config.axis_names, units=[a.unit for a in config.axes],
                positions=positions, loudness=np.zeros(n), tick_period=T,
                source=f"marionette.bench.climax seed {seed}")


def servo_fine(commands: np.ndarray, period: float, dead_time: float, tau: float,
               substeps: int = SUBSTEPS) -> np.ndarray:
    """Servo position [unit] every period/substeps [s], from the command at
    each tick [unit]: zero-order hold, dead time [s], first-order lag tau [s].
    Sample i is the position at time i*period/substeps."""
    dt = period / substeps
    delay = int(round(dead_time / dt))
    u = np.repeat(np.asarray(commands, dtype=float), substeps)
    u = np.concatenate([np.full(delay, u[0]), u])[: len(u)]
    if tau <= 0:
        return u
    # y[i+1] = y[i] + alpha*(u[i] - y[i]): exact for u held over each fine step
    beta = np.exp(-dt / tau)
    y = np.empty_like(u)
    y_prev = u[0]
    # blocks of a closed form keep this a few numpy calls per block
    block = 256
    powers = beta ** np.arange(1, block + 1)
    for s in range(0, len(u), block):
        chunk = u[s:s + block]
        m = len(chunk)
        p = powers[:m]
        # y[s+i] for i = 0..m-1 is y at the start of fine step s+i
        # y_{s+i+1} = beta^(i+1) y_s + (1-beta) * sum_{l<=i} beta^(i-l) u_{s+l}
        acc = np.empty(m)
        conv = np.convolve(chunk, beta ** np.arange(m))[:m]
        acc[:] = p * y_prev + (1 - beta) * conv
        y[s] = y_prev
        y[s + 1:s + m] = acc[:-1]
        y_prev = acc[-1]
    return y


def shaped_climaxes(points: np.ndarray, moves: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(ticks, kinds) of the points of rest that are still extrema of the
    shaped trajectory (a reduced excursion can turn a climax into a step)."""
    if not len(moves):
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    planned = np.concatenate([moves["x0"][:1], moves["x1"]])          # [unit]
    rise = np.sign(np.diff(planned))
    kind = np.zeros(len(planned), dtype=np.int64)
    kind[1:-1] = np.where(rise[:-1] * rise[1:] < 0, rise[:-1], 0).astype(np.int64)
    keep = kind != 0
    return points["tick"][keep], kind[keep]


def _climax_times(y: np.ndarray, kind: np.ndarray, ticks: np.ndarray, substeps: int) -> np.ndarray:
    """Time [ticks] of the servo's extremum of each climax's kind nearest its
    tick, between the neighbouring climaxes; NaN when there is none."""
    out = np.full(len(ticks), np.nan)
    n = len(y)
    for i, (k, sign) in enumerate(zip(ticks, kind)):
        lo = (ticks[i - 1] if i > 0 else 0) * substeps
        hi = min(n - 1, (ticks[i + 1] if i + 1 < len(ticks) else n // substeps) * substeps)
        seg = sign * y[lo:hi + 1]
        # local maxima of sign*y; a plateau counts at its first sample
        inner = np.flatnonzero((seg[1:-1] > seg[:-2]) & (seg[1:-1] >= seg[2:])) + 1
        if not inner.size:
            continue
        c = inner[np.argmin(np.abs(inner + lo - k * substeps))]
        y0, y1, y2 = seg[c - 1], seg[c], seg[c + 1]
        den = y0 - 2 * y1 + y2                   # parabola through the three samples
        frac = 0.5 * (y0 - y2) / den if den != 0 else 0.0
        out[i] = (lo + c + frac) / substeps
    return out


def shaped_fine(moves: np.ndarray, n_ticks: int, period: float, substeps: int) -> np.ndarray:
    """The shaped trajectory [unit] every period/substeps [s], exactly from its moves."""
    t = np.arange(n_ticks * substeps) * (period / substeps)
    x = np.full(t.size, moves["x0"][0] if len(moves) else 0.0)
    for m in moves:
        sel = t >= m["t0"]
        x[sel] = _shape.evaluate(m, t[sel])[0]
    return x


def _aligned_shifts(y: np.ndarray, x: np.ndarray, ticks: np.ndarray, substeps: int) -> np.ndarray:
    """Per climax tick, the shift [ticks] of y against x that best aligns
    them (least squares) near the climax; NaN where the window is too short."""
    out = np.full(len(ticks), np.nan)
    max_shift = MAX_SHIFT_TICKS * substeps
    shifts = np.arange(-max_shift, max_shift + 1)
    y = np.pad(y, max_shift, mode="edge")          # at rest before and after the run
    x = np.pad(x, max_shift, mode="edge")
    for i, k in enumerate(ticks):
        half = ALIGN_TICKS
        if i > 0:
            half = min(half, (k - ticks[i - 1]) // 2)
        if i + 1 < len(ticks):
            half = min(half, (ticks[i + 1] - k) // 2)
        lo, hi = (k - half) * substeps + max_shift, (k + half) * substeps + 1 + max_shift
        if half < 1:
            continue
        rows = np.lib.stride_tricks.sliding_window_view(y[lo - max_shift:hi + max_shift], hi - lo)
        cost = np.sum((rows - x[lo:hi]) ** 2, axis=1)         # one row per shift
        c = int(np.argmin(cost))
        frac = 0.0
        if 0 < c < len(cost) - 1:
            den = cost[c - 1] - 2 * cost[c] + cost[c + 1]
            frac = 0.5 * (cost[c - 1] - cost[c + 1]) / den if den > 0 else 0.0
        out[i] = (shifts[c] + frac) / substeps
    return out


def servo_timing(config: FigureConfig, taught: Show, lead: str, substeps: int = SUBSTEPS):
    """taught shaped for lead (policy reduce, rest tolerance 0), played through
    the engine, each axis's commands into a simulated servo. Returns
    (timing, shaping report): timing's "extremum" and "alignment" are the
    climaxes' errors [ticks] (NaN: no extremum found), "turning" whether each
    climax is a turn (the vertex of a parabola), "limited" the axis-ticks the
    engine's limits acted on."""
    T = config.tick_period
    shaped, report = shape_show(taught, config, policy="reduce", rest_tolerance=0.0, lead=lead)
    with Engine(config, shaped, lead=lead, record=True) as engine:
        engine.step(shaped.n_ticks)
        records = engine.records()
    extremum, aligned, turning = [np.zeros(0)], [np.zeros(0)], [np.zeros(0, dtype=bool)]
    for j, a in enumerate(config.axes):
        moves = report.axes[j].moves
        ticks, kinds = shaped_climaxes(report.axes[j].points, moves)
        if not len(ticks):
            continue
        y = servo_fine(records["command"][:, j], T, max(0.0, a.dead_time - T / 2), a.time_constant,
                       substeps)
        x = shaped_fine(moves, shaped.n_ticks, T, substeps)
        aligned.append(_aligned_shifts(y, x, ticks, substeps))
        extremum.append(_climax_times(y, kinds, ticks, substeps) - ticks)
        arriving = moves[np.searchsorted(moves["arrive_tick"], ticks)]
        turning.append(arriving["open"] & _shape.OPEN_END > 0)
    timing = {"extremum": np.concatenate(extremum), "alignment": np.concatenate(aligned),
              "turning": np.concatenate(turning),
              "limited": int(np.count_nonzero(records["excess"]))}
    return timing, report


def climax_timing(config: FigureConfig | None = None, seed: int = SEED,
                  seconds: float = SECONDS, substeps: int = SUBSTEPS) -> dict:
    """Climax timing errors [ticks] of the servos, with and without compensation."""
    config = config if config is not None else load_config()
    taught = random_dance(config, seconds, seed)
    result: dict = {}
    for label, lead in (("compensated", "dead_time_lag"), ("uncompensated", "none")):
        timing, shaping = servo_timing(config, taught, lead, substeps)
        if lead == "dead_time_lag":
            report, turning = shaping, timing["turning"]
        result[f"limited_axis_ticks_{label}"] = timing["limited"]
        for key in ("extremum", "alignment"):
            err = np.abs(timing[key])
            name = "climax" if key == "extremum" else key
            result[f"{name}_error_ticks_max_{label}"] = float(np.nanmax(err))
            result[f"{name}_error_ticks_median_{label}"] = float(np.nanmedian(err))
            result[f"{name}_unmatched_{label}"] = int(np.count_nonzero(np.isnan(err)))
    result.update(
        climaxes=len(turning), turning=int(np.count_nonzero(turning)),
        moves=report.segments, infeasible=len(report.infeasible), seconds=seconds, seed=seed,
        figure=config.name, target_ticks=TARGET_TICKS,
        target_met=bool(result["climax_error_ticks_max_compensated"] <= TARGET_TICKS))
    return result


def format_table(r: dict) -> str:
    lines = [f"climax timing on {r['figure']}: {r['climaxes']} climaxes in a {r['seconds']:g} s "
             f"random dance (seed {r['seed']}), {r['turning']} of them turning (the rest flat), "
             f"{r['infeasible']} of {r['moves']} moves infeasible (reduced) when shaped for "
             "dead_time_lag",
             f"  {'lead':<16}{'max |error| [ticks]':>22}{'median':>9}{'alignment max':>15}"
             f"{'median':>9}{'limited':>10}"]
    for label, lead in (("compensated", "dead_time_lag"), ("uncompensated", "none")):
        lines.append(f"  {lead:<16}{r[f'climax_error_ticks_max_{label}']:>22.3f}"
                     f"{r[f'climax_error_ticks_median_{label}']:>9.3f}"
                     f"{r[f'alignment_error_ticks_max_{label}']:>15.3f}"
                     f"{r[f'alignment_error_ticks_median_{label}']:>9.3f}"
                     f"{r[f'limited_axis_ticks_{label}']:>10d}")
    lines.append("  error: the servo's extremum's time less the climax's; alignment: the shift "
                 "that aligns the servo's motion near each climax with the show's (docstring)")
    lines.append(f"  target: max <= {r['target_ticks']:g} tick compensated: "
                 f"{'met' if r['target_met'] else 'MISSED'}")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="marionette bench climax",
        description="Timing error [ticks] of the shaped climaxes on simulated servos, "
                    "with and without dead-time/lag compensation.")
    parser.add_argument("--json", action="store_true", help="print JSON instead of the table")
    parser.add_argument("--config", help="figure TOML; default: the bundled Hoffmann 1996 figure")
    parser.add_argument("--seed", type=int, default=SEED, help="seed of the random dance")
    parser.add_argument("--seconds", type=float, default=SECONDS, help="length of the dance [s]")
    parser.add_argument("--strict", action="store_true", help="exit 1 if the target is missed")
    args = parser.parse_args(argv)
    if not args.seconds > 0:
        parser.error("--seconds must be > 0")
    r = climax_timing(load_config(args.config), args.seed, args.seconds)
    if args.json:
        json.dump(r, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        print(format_table(r))
    return 1 if args.strict and not r["target_met"] else 0


if __name__ == "__main__":
    sys.exit(main())
