"""``marionette bench tick``: compute time per tick [us] in step mode.

For 16, 256 and 4096 axes: a synthetic figure (limits wide enough that the
limiter stays inactive) and a synthetic show, played at a fractional rate
(0.75 show ticks per tick, so every sample is interpolated) with cubic
sampling and the dead_time_lag lead, i.e. the costliest path of the tick.

- the C engine's step mode times each tick itself (clock_gettime around
  mar_engine_tick) into its log-linear 'compute' histogram (~1.6 % relative
  resolution): median and p99.9 [us] come from ``engine.stats()["compute"]``;
- the numpy reference tick (marionette.bench.reference) runs the same figure,
  show and ticks afterwards, timed per tick with time.perf_counter_ns [ns],
  garbage collector off;
- speedup = reference median / engine median [1].

The show is 1500 show ticks (30 s at 20 ms) per axis; when the playback
position nears its end both engines seek back to 0, at the same ticks, so
long runs need no more memory. At the end the engine's last commands are
compared with the reference's (max_abs_diff [unit], expected 0).

JSON (``--json``): a list of rows, one per axis count, with the keys
axes, median_us, p999_us, reference_median_us, speedup, and extra keys
(ticks, p99_us, max_us, reference_p999_us, limited_fraction, max_abs_diff,
targets, machine).
"""
from __future__ import annotations

import gc
import json
import sys
import time

import numpy as np

from marionette.bench import STRICT_HELP, exit_status, verdict
from marionette.bench._machine import describe, machine_info
from marionette.bench.reference import ReferenceEngine
from marionette.cli.options import SEED as SEED_OPTION, Number
from marionette.config import FigureConfig, config_from_dict
from marionette.engine import Engine
from marionette.show import Show

SIZES = (16, 256, 4096)                                 # axes
DEFAULT_TICKS = {16: 20000, 256: 20000, 4096: 5000}     # ticks per size
QUICK_TICKS = {16: 200, 256: 100, 4096: 20}
SHOW_TICKS = 1500          # synthetic show length [show ticks]
QUICK_SHOW_TICKS = 100
RATE = 0.75                # playback rate [show ticks per tick]
PERIOD = 0.020             # tick period [s]
SEED = 20261122
WARM_UP_S = 0.3            # busy time before each size [s]

# Targets: (axes, row key, bound, "<=" or ">="); times in us, speedup in 1.
TARGETS = ((16, "median_us", 5.0, "<="), (16, "p999_us", 50.0, "<="),
           (4096, "median_us", 1000.0, "<="), (16, "speedup", 50.0, ">="))


def synthetic(n_axes: int, show_ticks: int = SHOW_TICKS, seed: int = SEED) -> tuple[FigureConfig, Show]:
    """A figure of n_axes axes and a smooth show for it.

    Limits: position [-1, 1] unit, top speed 1000 unit/s, top acceleration
    1e6 unit/s^2, so the limiter stays inactive; dead time 20..100 ms and
    time constant 20..200 ms. Show: per axis a sum of two sines, 0.1..1 Hz,
    amplitude <= 0.8 unit, so positions stay inside the limits.
    """
    rng = np.random.default_rng(seed + n_axes)
    dead = rng.uniform(0.02, 0.10, n_axes)          # [s]
    tau = rng.uniform(0.02, 0.20, n_axes)           # [s]
    axes = [dict(name=f"a{j:04d}", node=j // 256, channel=j % 256, unit="m" if j % 2 else "rad",
                 min=-1.0, max=1.0, home=0.0, max_speed=1000.0, max_accel=1e6,
                 dead_time=float(dead[j]), time_constant=float(tau[j]), scale=1000.0)
            for j in range(n_axes)]
    config = config_from_dict({"figure": {"name": f"bench{n_axes}", "tick_period": PERIOD},
                               "axis": axes}, f"<bench {n_axes} axes>")
    t = np.arange(show_ticks) * PERIOD                                   # [s]
    freq = rng.uniform(0.1, 1.0, (n_axes, 2, 1))                         # [Hz]
    phase = rng.uniform(0.0, 2 * np.pi, (n_axes, 2, 1))                  # [rad]
    positions = 0.4 * np.sin(2 * np.pi * freq * t + phase).sum(axis=1)   # [unit], |x| <= 0.8
    loudness = 0.5 + 0.4 * np.sin(2 * np.pi * 0.5 * t)                   # [1]
    show = Show(axis_names=config.axis_names, units=[a["unit"] for a in axes],
                positions=positions, loudness=loudness, tick_period=PERIOD, source="bench")
    return config, show


def _segment(config: FigureConfig, show_ticks: int, rate: float) -> int:
    """Ticks [ticks] to play before seeking back to 0, so the position
    (plus the largest lead) stays inside the show."""
    lead = max(a.dead_time for a in config.axes) / config.tick_period        # [show ticks at rate 1]
    return max(1, int((show_ticks - 2 - rate * lead) / rate))


def warm_up(ref: ReferenceEngine, seconds: float) -> None:
    """Keep the CPU busy for seconds [s] (untimed reference ticks), so that
    frequency scaling and the host settle before anything is timed."""
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        ref.tick()


def bench_size(n_axes: int, ticks: int, show_ticks: int = SHOW_TICKS, rate: float = RATE,
               seed: int = SEED, warm_up_s: float = WARM_UP_S) -> dict:
    """One row: the C engine then the numpy reference, same figure, show, ticks."""
    config, show = synthetic(n_axes, show_ticks, seed)
    segment = _segment(config, show_ticks, rate)

    engine = Engine(config, show, rate=rate)     # cubic, dead_time_lag: the costliest path
    fitted = engine.show
    warm_up(ReferenceEngine(config, fitted, rate=rate, fitted=True), warm_up_s)
    try:
        done = 0
        while done < ticks:
            k = min(segment, ticks - done)
            engine.step(k)
            done += k
            if done < ticks:
                engine.seek(0.0)
        stats = engine.stats()
        snap = engine.snapshot()
        ours = np.array([snap.commands[name] for name in config.axis_names])   # [unit]
    finally:
        engine.close()
    compute = stats["compute"]

    ref = ReferenceEngine(config, fitted, rate=rate, fitted=True)
    times = np.empty(ticks, dtype=np.int64)      # [ns]
    gc_was_on = gc.isenabled()
    gc.disable()
    try:
        clock = time.perf_counter_ns
        for k in range(ticks):
            if k and k % segment == 0:
                ref.seek(0.0)
            t0 = clock()
            ref.tick()
            times[k] = clock() - t0
    finally:
        if gc_was_on:
            gc.enable()
    ref_median = float(np.median(times)) / 1e3                              # [us]
    ref_p999 = float(np.quantile(times, 0.999, method="inverted_cdf")) / 1e3  # [us]

    median = compute["p50_us"]
    return {
        "axes": n_axes,
        "median_us": median,
        "p999_us": compute["p999_us"],
        "reference_median_us": ref_median,
        "speedup": ref_median / median if median > 0 else float("inf"),
        "ticks": int(compute["count"]),
        "p99_us": compute["p99_us"],
        "max_us": compute["max_us"],
        "reference_p999_us": ref_p999,
        "limited_fraction": stats["limited"] / (ticks * n_axes),     # axis-ticks limited [1]
        "max_abs_diff": float(np.max(np.abs(ours - ref.command))),     # last tick [unit]
    }


def check_targets(rows: list[dict]) -> list[tuple[str, float, bool]]:
    """(label, measured value, passed) per target whose axis count was run;
    also stores the verdicts in each row's 'targets'."""
    out = []
    by_axes = {row["axes"]: row for row in rows}
    for axes, key, bound, op in TARGETS:
        row = by_axes.get(axes)
        if row is None:
            continue
        value = row[key]
        ok = value <= bound if op == "<=" else value >= bound
        label = f"{axes} axes: {key} {op} {bound:g}"
        row.setdefault("targets", {})[f"{key} {op} {bound:g}"] = ok
        out.append((label, value, ok))
    return out


def collect(sizes=SIZES, ticks: int | None = None, quick: bool = False, seed: int = SEED) -> list[dict]:
    """Rows for each axis count (see the module docstring); ticks overrides
    the per-size defaults, quick uses tiny counts (smoke tests)."""
    machine = machine_info()
    rows = []
    for n in sizes:
        n_ticks = ticks if ticks is not None else (QUICK_TICKS if quick else DEFAULT_TICKS).get(n, 5000)
        row = bench_size(n, n_ticks, QUICK_SHOW_TICKS if quick else SHOW_TICKS, RATE, seed,
                         0.0 if quick else WARM_UP_S)
        row["machine"] = machine
        rows.append(row)
    check_targets(rows)
    return rows


def format_table(rows: list[dict]) -> str:
    lines = [f"marionette bench tick: compute time per tick, step mode "
             f"(cubic, dead_time_lag lead, rate {RATE} show ticks per tick, {PERIOD * 1e3:g} ms period)"]
    if rows:
        lines.append(describe(rows[0]["machine"]))
    lines.append("")
    lines.append(f"{'axes':>6} {'ticks':>7} {'median_us':>10} {'p99_us':>9} {'p999_us':>9} "
                 f"{'max_us':>9} {'ref_median_us':>14} {'ref_p999_us':>12} {'speedup':>8} "
                 f"{'limited':>8} {'diff':>8}")
    for r in rows:
        lines.append(f"{r['axes']:>6} {r['ticks']:>7} {r['median_us']:>10.3f} {r['p99_us']:>9.3f} "
                     f"{r['p999_us']:>9.3f} {r['max_us']:>9.1f} {r['reference_median_us']:>14.2f} "
                     f"{r['reference_p999_us']:>12.1f} {r['speedup']:>7.1f}x "
                     f"{r['limited_fraction']:>8.2%} {r['max_abs_diff']:>8.1g}")
    lines.append("")
    lines.append("engine times: the C step loop's compute histogram (~1.6 % resolution); reference: "
                 "numpy, perf_counter_ns per tick; diff: |engine - reference| last commands [unit]")
    lines.append("targets:")
    for label, value, ok in check_targets(rows):
        lines.append(f"  {label:<34} measured {value:>10.3f}   {verdict(ok)}")
    return "\n".join(lines)


def register(sub) -> None:
    parser = sub.add_parser(
        "tick", help="compute time per tick, C engine vs the numpy reference",
        description="Compute time per tick [us] of the C engine in step mode, against the "
                    "numpy reference tick, for 16, 256 and 4096 axes.")
    parser.add_argument("--json", action="store_true",
                        help="print a JSON list of rows instead of the table")
    parser.add_argument("--quick", action="store_true",
                        help="tiny tick counts and a short show (smoke test; numbers meaningless)")
    parser.add_argument("--axes", type=Number(int, 1, 65536), nargs="+", default=list(SIZES), metavar="N",
                        help="axis counts to run (default: 16 256 4096)")
    parser.add_argument("--ticks", type=Number(int, 1), default=None, metavar="N",
                        help="ticks per axis count (default: 20000 for 16 and 256 axes, 5000 for 4096)")
    parser.add_argument("--seed", type=SEED_OPTION, default=SEED,
                        help="seed of the synthetic figure and show")
    parser.add_argument("--strict", action="store_true", help=STRICT_HELP)


def run(args) -> int:
    rows = collect(args.axes, args.ticks, args.quick, args.seed)
    if args.json:
        json.dump(rows, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        print(format_table(rows))
    return exit_status((ok for row in rows for ok in row.get("targets", {}).values()), args.strict)


def main(argv=None) -> int:
    """``python -m marionette.bench.tick``: as ``marionette bench tick``."""
    from marionette.cli import main as cli_main
    return cli_main(["bench", "tick", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
