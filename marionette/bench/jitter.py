"""``marionette bench jitter``: wake latency of the real-time loop [us].

Three kinds of run, each ``--seconds`` long in all at the figure's tick
period (20 ms for the bundled figure) and the same SCHED_FIFO priority.
They are interleaved in ``--rounds`` rounds (engine, cyclictest, engine
under GIL load, then again), and each kind's samples are merged over its
rounds, so that a burst of noise from the host lands on all three alike
rather than on whichever happened to run at that moment:

1. ``engine``: the bundled figure playing the demo show in the real-time
   loop (``engine.start(priority=P, lock_memory=True, max_ticks=N)``); the
   loop records, every tick, how late it woke after its absolute deadline
   (``engine.stats()["wake"]``, a log-linear histogram of ~1.6 % relative
   resolution: percentiles are bucket midpoints, the max is exact) and counts
   missed deadlines (``overruns``);
2. ``cyclictest`` (Debian rt-tests): one thread, same period, priority,
   loop count and memory locking, ``--default-system`` so that, like the
   engine, it leaves the power management (/dev/cpu_dma_latency) alone;
   ``-v -N`` prints every latency [ns], from which the same nearest-rank
   percentiles are taken exactly (no overrun count: null). null when
   cyclictest is not installed;
3. ``engine_gil_load``: the engine again while two Python threads churn the
   GIL and the allocator (building lists, dicts and strings in busy loops).

JSON (``--json``): {"engine", "cyclictest", "engine_gil_load"}: each
{p50_us, p99_us, p999_us, max_us, overruns, count, ...} or null; plus
"machine", "seconds", "period_s", "priority", "targets".

Targets: the engine's p99 at most 50 us above cyclictest's p99 and its max
at most 2x cyclictest's max; the GIL load raises the engine's p99 by < 20 us.
That last one is one-sided on purpose: busy CPUs often wake *faster* than
idle ones (an idle CPU sits in a C-state, an idle vCPU is halted and must
be rescheduled by the host), so the load can lower the latency by far more
than 20 us without saying anything about the GIL; the signed change is
printed (and is in the JSON as "gil_p99_change_us").
"""
from __future__ import annotations

import contextlib
import json
import math
import os
import re
import shutil
import subprocess
import sys
import threading
import warnings

import numpy as np

from marionette.bench import STRICT_HELP, exit_status, verdict
from marionette.bench._machine import describe, machine_info
from marionette.bench.shield import shield
from marionette.cli.options import Number
from marionette.config import load_config
from marionette.demo import DEMO_SHOW
from marionette.engine import Engine
from marionette.errors import ArgumentError, MarionetteError
from marionette.show import load_show

PRIORITY = 80             # SCHED_FIFO priority of the tick thread and of cyclictest [1..99]
SECONDS = 20.0            # length of each kind of run, all rounds together [s]
ROUNDS = 4                # interleaved rounds
CHURN_THREADS = 2         # Python threads loading the GIL in the third run

_SAMPLE = re.compile(r"^\s*(\d+):\s*(\d+):\s*(\d+)\s*$")          # thread:count:latency (-v)
_SUMMARY = re.compile(r"^T:\s*\d+.*C:\s*(\d+).*Min:\s*(\d+).*Avg:\s*(\d+).*Max:\s*(\d+)")


def _nearest_rank(sorted_ns: np.ndarray, q: float) -> float:
    """Latency [ns] at quantile q in [0, 1] of sorted latencies [ns]: the sample
    of rank ceil(q*n) (1-based), the rank the engine's histogram takes."""
    n = len(sorted_ns)
    rank = min(max(math.ceil(q * n), 1), n)
    return float(sorted_ns[rank - 1])


def _engine_run(ticks: int, priority: int, lock_memory: bool, churn: int = 0,
                cpu: int | None = None) -> dict:
    """Wake latency [us] of the real-time loop over ticks ticks, with churn
    Python threads loading the GIL meanwhile."""
    config = load_config()                       # bundled figure, 16 axes, 20 ms
    show = load_show(DEMO_SHOW, config)           # the 20 s demo show
    stop = threading.Event()

    def churn_loop() -> None:
        # Busy Python work: holds the GIL most of the time, allocates and frees.
        while not stop.is_set():
            items = [i * 3 for i in range(2000)]
            table = {i: str(i) for i in range(500)}
            items.extend(table.values())
            del items, table

    threads = [threading.Thread(target=churn_loop, name=f"gil-churn-{k}", daemon=True)
               for k in range(churn)]
    engine = Engine(config, show)
    try:
        for t in threads:
            t.start()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            report = engine.start(priority=priority, cpu=cpu, lock_memory=lock_memory,
                                  max_ticks=ticks)
        period = config.tick_period               # [s]
        if not engine.wait(timeout=ticks * period + 30.0):
            raise MarionetteError("the real-time loop did not finish its ticks in time")
        stats = engine.stats()
        histogram = engine.histogram("wake")
    finally:
        stop.set()
        for t in threads:
            t.join()
        engine.close()
    wake = stats["wake"]
    return {
        "p50_us": wake["p50_us"], "p99_us": wake["p99_us"], "p999_us": wake["p999_us"],
        "max_us": wake["max_us"], "overruns": int(stats["overruns"]), "count": int(wake["count"]),
        "_histogram": histogram,
        "compute_p99_us": stats["compute"]["p99_us"],      # tick body [us], for context
        "fifo": bool(report.get("fifo")), "memory_locked": bool(report.get("memory_locked")),
        "pinned": bool(report.get("pinned")),
        "warnings": [str(w.message) for w in caught],
        "churn_threads": churn,
    }


def _cyclictest_run(ticks: int, period: float, priority: int, lock_memory: bool,
                    exe: str | None, cpu: int | None = None) -> dict | None:
    """cyclictest latency [us] over as many loops at the same period; None if absent."""
    exe = shutil.which(exe or "cyclictest")
    if exe is None:
        return None
    interval_us = int(round(period * 1e6))
    cmd = [exe, "-t1", "-p", str(priority), "-i", str(interval_us), "-l", str(ticks),
           "-q", "-v", "-N", "--default-system"] + (["-m"] if lock_memory else []) \
        + ([] if cpu is None else ["-a", str(cpu)])
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=ticks * period + 60.0)
    if done.returncode != 0:
        raise MarionetteError(f"{' '.join(cmd)} failed with status {done.returncode}: "
                              f"{done.stderr.strip() or done.stdout.strip()}")
    samples, summary = [], None
    for line in done.stdout.splitlines():
        m = _SAMPLE.match(line)
        if m:
            samples.append(int(m.group(3)))
        elif (m := _SUMMARY.match(line.strip())):
            summary = {"count": int(m.group(1)), "min_ns": int(m.group(2)),
                       "avg_ns": int(m.group(3)), "max_ns": int(m.group(4))}
    if not samples:
        raise MarionetteError(f"{' '.join(cmd)} printed no latencies:\n{done.stdout[-2000:]}")
    ns = np.sort(np.array(samples, dtype=np.int64))          # [ns]
    peak = max(float(ns[-1]), float(summary["max_ns"]) if summary else 0.0)
    return {
        "p50_us": _nearest_rank(ns, 0.5) / 1e3, "p99_us": _nearest_rank(ns, 0.99) / 1e3,
        "p999_us": _nearest_rank(ns, 0.999) / 1e3, "max_us": peak / 1e3,
        "overruns": None,                      # cyclictest does not count missed periods
        "count": len(samples),
        "command": " ".join(cmd),
        "_ns": ns,
    }


def _hist_quantile(lower, width, counts, peak, q: float) -> float:
    """Latency [ns] at quantile q of a merged engine histogram, by the C rule
    (mar_hist_quantile): the bucket of rank ceil(q*n), its midpoint, capped at the max."""
    total = int(counts.sum())
    rank = min(max(math.ceil(q * total), 1), total)
    i = int(np.searchsorted(np.cumsum(counts), rank))
    return float(min(lower[i] + width[i] // 2, peak))


def merge_engine_runs(runs: list[dict]) -> dict:
    """One engine result from several rounds: histograms summed."""
    lower, width = runs[0]["_histogram"][:2]
    counts = sum(r["_histogram"][2].astype(np.int64) for r in runs)
    peak = max(r["_histogram"][3] for r in runs)
    out = dict(runs[-1])
    out.update({f"{name}_us": _hist_quantile(lower, width, counts, peak, q) / 1e3
                for name, q in (("p50", 0.5), ("p99", 0.99), ("p999", 0.999))})
    out.update(max_us=peak / 1e3, count=int(counts.sum()),
               overruns=sum(r["overruns"] for r in runs),
               compute_p99_us=max(r["compute_p99_us"] for r in runs),
               warnings=sorted({w for r in runs for w in r["warnings"]}))
    del out["_histogram"]
    return out


def merge_cyclictest_runs(runs: list[dict]) -> dict:
    """One cyclictest result from several rounds: samples pooled."""
    ns = np.sort(np.concatenate([r["_ns"] for r in runs]))
    out = dict(runs[-1])
    out.update(p50_us=_nearest_rank(ns, 0.5) / 1e3, p99_us=_nearest_rank(ns, 0.99) / 1e3,
               p999_us=_nearest_rank(ns, 0.999) / 1e3,
               max_us=max(r["max_us"] for r in runs), count=len(ns))
    del out["_ns"]
    return out


def check_targets(result: dict) -> list[tuple[str, str, bool | None]]:
    """(label, measured, passed or None when not measurable) per target."""
    eng, ct, gil = result["engine"], result["cyclictest"], result["engine_gil_load"]
    out = []
    if ct is None:
        out.append(("engine p99 <= cyclictest p99 + 50 us", "no cyclictest run", None))
        out.append(("engine max <= 2 x cyclictest max", "no cyclictest run", None))
    else:
        d = eng["p99_us"] - ct["p99_us"]
        out.append(("engine p99 <= cyclictest p99 + 50 us",
                    f"{eng['p99_us']:.1f} vs {ct['p99_us']:.1f} us ({d:+.1f} us)", d <= 50.0))
        ratio = eng["max_us"] / ct["max_us"] if ct["max_us"] > 0 else math.inf
        out.append(("engine max <= 2 x cyclictest max",
                    f"{eng['max_us']:.1f} vs {ct['max_us']:.1f} us ({ratio:.2f}x)", ratio <= 2.0))
    d = gil["p99_us"] - eng["p99_us"]
    out.append(("GIL load raises engine p99 by < 20 us",
                f"{gil['p99_us']:.1f} vs {eng['p99_us']:.1f} us ({d:+.1f} us)", d < 20.0))
    return out


def collect(seconds: float = SECONDS, priority: int = PRIORITY, lock_memory: bool = True,
            cyclictest: str | None = "cyclictest", churn_threads: int = CHURN_THREADS,
            cpu: int | None = None, rounds: int = ROUNDS) -> dict:
    """The three kinds of run (see the module docstring), seconds [s] each
    in all, interleaved in rounds; cpu pins the tick thread and cyclictest
    to that CPU (None: not pinned)."""
    period = load_config().tick_period                        # [s]
    ticks = max(1, int(round(seconds / period)))
    if not cyclictest:
        note = "skipped (--no-cyclictest)"
    elif shutil.which(cyclictest) is None:
        note = f"{cyclictest} not found (Debian: apt install rt-tests)"
    else:
        note = None
    per_round = max(1, ticks // rounds)
    engine_runs, ct_runs, gil_runs = [], [], []
    for _ in range(rounds):
        engine_runs.append(_engine_run(per_round, priority, lock_memory, 0, cpu))
        if note is None:
            try:
                ct_runs.append(_cyclictest_run(per_round, period, priority, lock_memory,
                                               cyclictest, cpu))
            except (RuntimeError, OSError, subprocess.TimeoutExpired) as exc:  # e.g. no SCHED_FIFO
                note = f"failed: {exc}"
        gil_runs.append(_engine_run(per_round, priority, lock_memory, churn_threads, cpu))
    result = {
        "engine": merge_engine_runs(engine_runs),
        "cyclictest": merge_cyclictest_runs(ct_runs) if note is None else None,
        "engine_gil_load": merge_engine_runs(gil_runs),
        "cyclictest_note": note,
        "machine": machine_info(),
        "seconds": seconds,
        "period_s": period,
        "priority": priority,
        "ticks": per_round * rounds,
        "rounds": rounds,
        "memory_locked": lock_memory,
        "cpu": cpu,
    }
    result["gil_p99_change_us"] = result["engine_gil_load"]["p99_us"] - result["engine"]["p99_us"]
    result["targets"] = {label: ok for label, _, ok in check_targets(result)}
    return result


def format_table(result: dict) -> str:
    lines = [f"marionette bench jitter: wake latency at the {result['period_s'] * 1e3:g} ms period, "
             f"SCHED_FIFO priority {result['priority']}, {result['seconds']:g} s "
             f"({result['ticks']} ticks) per run, memory "
             f"{'locked' if result['memory_locked'] else 'not locked'}, "
             f"{'pinned to CPU %d' % result['cpu'] if result['cpu'] is not None else 'not pinned'}"
             + (f", shielded ({result['shield']['moved']} tasks moved off)" if result.get("shield") else ""),
             describe(result["machine"]), "",
             f"{'run':<18} {'count':>6} {'p50_us':>8} {'p99_us':>8} {'p999_us':>8} {'max_us':>8} "
             f"{'overruns':>8}"]
    for key in ("engine", "cyclictest", "engine_gil_load"):
        r = result[key]
        if r is None:
            lines.append(f"{key:<18} ({result.get('cyclictest_note') or 'not run'})")
            continue
        over = "-" if r["overruns"] is None else str(r["overruns"])
        lines.append(f"{key:<18} {r['count']:>6} {r['p50_us']:>8.1f} {r['p99_us']:>8.1f} "
                     f"{r['p999_us']:>8.1f} {r['max_us']:>8.1f} {over:>8}")
    lines.append("")
    lines.append("engine: log-linear histogram, ~1.6 % resolution (max exact); cyclictest: "
                 "every sample [ns] (-v -N), nearest rank")
    for key in ("engine", "engine_gil_load"):
        r = result[key]
        notes = [] if r["fifo"] else ["NOT SCHED_FIFO"]
        notes += r["warnings"]
        if notes:
            lines.append(f"{key}: " + "; ".join(notes))
    if result["cyclictest"] is not None:
        lines.append(f"cyclictest: {result['cyclictest']['command']}")
    elif result.get("cyclictest_note"):
        lines.append(f"cyclictest: {result['cyclictest_note']}")
    if result["gil_p99_change_us"] <= -20.0:
        lines.append("engine_gil_load is faster: busy CPUs wake sooner than idle (halted) ones; "
                     "an effect of idle states, not of the GIL")
    lines.append("targets:")
    for label, measured, ok in check_targets(result):
        lines.append(f"  {label:<40} {measured:<36} {verdict(ok)}")
    return "\n".join(lines)


def register(sub) -> None:
    parser = sub.add_parser(
        "jitter", help="wake latency of the real-time loop, beside cyclictest",
        description="Wake latency [us] of the real-time loop, beside cyclictest at the same "
                    "period and priority, and under Python threads loading the GIL.")
    parser.add_argument("--seconds", type=Number(float, 0.0, above=True), default=SECONDS, metavar="N",
                        help=f"length of each of the three runs [s] (default {SECONDS:g})")
    parser.add_argument("--priority", type=Number(int, 1, 99), default=PRIORITY, metavar="P",
                        help=f"SCHED_FIFO priority (default {PRIORITY})")
    parser.add_argument("--no-mlock", action="store_true",
                        help="do not lock memory (engine lock_memory, cyclictest -m)")
    parser.add_argument("--cpu", type=Number(int, 0, (os.cpu_count() or 1) - 1), default=None, metavar="N",
                        help="pin the tick thread and cyclictest to CPU N (default: not pinned)")
    parser.add_argument("--shield", action="store_true",
                        help="with --cpu: move every other task of the machine off CPU N for the run "
                             "(root, cpuset; marionette/bench/shield.py)")
    parser.add_argument("--cyclictest", default="cyclictest", metavar="PATH",
                        help="cyclictest executable (default: found on PATH)")
    parser.add_argument("--no-cyclictest", action="store_true", help="skip the cyclictest run")
    parser.add_argument("--rounds", type=Number(int, 1), default=ROUNDS, metavar="R",
                        help=f"interleave the runs in R rounds (default {ROUNDS})")
    parser.add_argument("--json", action="store_true", help="print JSON instead of the table")
    parser.add_argument("--strict", action="store_true", help=STRICT_HELP)


def run(args) -> int:
    if args.shield and args.cpu is None:
        raise ArgumentError("bench jitter: --shield needs --cpu N")
    with shield(args.cpu) if args.shield else contextlib.nullcontext() as shielded:
        result = collect(args.seconds, args.priority, not args.no_mlock,
                         None if args.no_cyclictest else args.cyclictest, cpu=args.cpu,
                         rounds=max(1, args.rounds))
    result["shield"] = shielded
    if args.json:
        json.dump(result, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        print(format_table(result))
    return exit_status(result["targets"].values(), args.strict)


def main(argv=None) -> int:
    """``python -m marionette.bench.jitter``: as ``marionette bench jitter``."""
    from marionette.cli import main as cli_main
    return cli_main(["bench", "jitter", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
