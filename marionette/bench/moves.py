"""marionette bench moves: online moves against Ruckig, and climax timing.

1. On random state-to-target cases (fixed seed), the duration of our
   time-optimal moves (C, ext/mar_move.c) against Ruckig's time-optimal
   duration with the same speed and acceleration limits and unlimited jerk,
   and microseconds per call for both through Python. Each of our profiles is
   also sampled and checked against the limits (`violations`).
2. On simulated servos with dead time and lag, the timing error of the
   reached climaxes of a shaped show, with and without lead compensation
   (marionette.bench.climax).

Ruckig comes with the `bench` extra (pip install 'marionette[bench]').
"""
from __future__ import annotations

import json
import sys
import time

import numpy as np

from marionette._core import plan_move
from marionette.bench import STRICT_HELP, exit_status, verdict
from marionette.bench._machine import describe, machine_info
from marionette.cli.options import SEED as SEED_OPTION, Number
from marionette.errors import MarionetteError

CASES = 10_000
SEED = 20261122
# verdict None: not measured (Ruckig not installed)
TARGETS = {"duration_ratio_max <= 1.001": lambda r: None if r["duration_ratio_max"] is None
           else r["duration_ratio_max"] <= 1.001,
           "violations == 0": lambda r: r["violations"] == 0,
           "climax_error_ticks_max_compensated <= 1": lambda r: r["climax_error_ticks_max_compensated"] <= 1}


def random_cases(n: int, seed: int = SEED) -> np.ndarray:
    """Rows x0 [m], v0 [m/s], target [m], vmax [m/s], amax [m/s^2]."""
    rng = np.random.default_rng(seed)
    vmax = rng.uniform(0.05, 5.0, n)
    amax = rng.uniform(0.1, 50.0, n)
    x0, target = rng.uniform(-2.0, 2.0, (2, n))
    v0 = np.where(rng.random(n) < 0.8, rng.uniform(-1, 1, n) * vmax, 0.0)
    return np.column_stack([x0, v0, target, vmax, amax])


def violates(x0, v0, target, vmax, amax, duration, samples: int = 64) -> bool:
    """Sampled profile outside |v| <= vmax, |dv/dt| <= amax, or not ending at rest on target."""
    t = np.linspace(0.0, duration, samples)
    _, _, x, v = plan_move(x0, v0, target, vmax, amax, t)
    if x[-1] != target or v[-1] != 0.0:
        return True
    if np.any(np.abs(v) > vmax * (1 + 1e-9) + 1e-12):
        return True
    return bool(samples > 1 and duration > 0
                and np.any(np.abs(np.diff(v)) > amax * (t[1] - t[0]) * (1 + 1e-9) + 1e-12))


def ruckig_duration(otg, inp, traj, case) -> float:
    from ruckig import Result
    x0, v0, target, vmax, amax = map(float, case)
    inp.current_position, inp.current_velocity, inp.current_acceleration = [x0], [v0], [0.0]
    inp.target_position, inp.target_velocity, inp.target_acceleration = [target], [0.0], [0.0]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [vmax], [amax], [float("inf")]
    result = otg.calculate(inp, traj)
    if result not in (Result.Working, Result.Finished):
        raise MarionetteError(f"ruckig failed on {case}: {result}")
    return traj.duration


def compare_with_ruckig(cases: np.ndarray) -> dict:
    ours = np.empty(len(cases))
    ours_ns = np.empty(len(cases))
    for i, c in enumerate(cases):
        t0 = time.perf_counter_ns()
        ours[i] = plan_move(*c)[0]
        ours_ns[i] = time.perf_counter_ns() - t0
    violations = sum(violates(*c, d) for c, d in zip(cases, ours))
    out = {"cases": len(cases), "violations": int(violations),
           "us_per_call_median": float(np.median(ours_ns)) / 1e3,
           "duration_ratio_median": None, "duration_ratio_max": None,
           "ruckig_us_per_call_median": None, "ruckig": None}
    try:
        import ruckig
        from ruckig import InputParameter, Ruckig, Trajectory
    except ImportError:
        out["ruckig"] = "not installed (pip install 'marionette[bench]')"
        return out
    otg, inp, traj = Ruckig(1), InputParameter(1), Trajectory(1)
    theirs = np.empty(len(cases))
    theirs_ns = np.empty(len(cases))
    for i, c in enumerate(cases):
        t0 = time.perf_counter_ns()
        theirs[i] = ruckig_duration(otg, inp, traj, c)
        theirs_ns[i] = time.perf_counter_ns() - t0
    moving = theirs > 1e-9                     # already at rest on the target: both 0
    ratio = ours[moving] / theirs[moving]
    out.update(duration_ratio_median=float(np.median(ratio)), duration_ratio_max=float(ratio.max()),
               duration_ratio_min=float(ratio.min()),
               ruckig_us_per_call_median=float(np.median(theirs_ns)) / 1e3,
               ruckig=getattr(ruckig, "__version__", "installed"))
    return out


def collect(cases: int = CASES, seed: int = SEED, quick: bool = False) -> dict:
    result = compare_with_ruckig(random_cases(cases, seed))
    from marionette.bench.climax import climax_timing
    result.update(climax_timing(seed=seed, seconds=10.0) if quick else climax_timing(seed=seed))
    result["machine"] = machine_info()
    result["targets"] = {label: check(result) for label, check in TARGETS.items()}
    return result


def register(sub) -> None:
    parser = sub.add_parser(
        "moves", help="online moves against Ruckig, limit violations, climax timing",
        description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=Number(int, 1), default=CASES, help="random move cases")
    parser.add_argument("--seed", type=SEED_OPTION, default=SEED, help="seed of the random cases")
    parser.add_argument("--quick", action="store_true", help="small counts, for tests")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--strict", action="store_true", help=STRICT_HELP)


def run(args) -> int:
    result = collect(200 if args.quick else args.cases, args.seed, args.quick)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(f"marionette bench moves: {result['cases']} random moves (seed {args.seed})")
        print(describe(result["machine"]))
        r = result
        if r["duration_ratio_max"] is None:
            print(f"  ruckig: {r['ruckig']}")
        else:
            print(f"  duration ours / ruckig (jerk unlimited): median {r['duration_ratio_median']:.9f}  "
                  f"min {r['duration_ratio_min']:.9f}  max {r['duration_ratio_max']:.9f}  (ruckig {r['ruckig']})")
            print(f"  us per call through Python: ours {r['us_per_call_median']:.2f}  "
                  f"ruckig {r['ruckig_us_per_call_median']:.2f}")
        print(f"  limit violations in our sampled profiles: {r['violations']}")
        print(f"  climax timing error [ticks]: max {r['climax_error_ticks_max_compensated']:.3f} compensated, "
              f"{r['climax_error_ticks_max_uncompensated']:.3f} uncompensated")
        for label, ok in r["targets"].items():
            print(f"  target {label:<45} {verdict(ok)}")
    return exit_status(result["targets"].values(), args.strict)


def main(argv=None) -> int:
    """``python -m marionette.bench.moves``: as ``marionette bench moves``."""
    from marionette.cli import main as cli_main
    return cli_main(["bench", "moves", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
