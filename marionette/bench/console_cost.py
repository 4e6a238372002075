"""``marionette bench console-cost``: the live console's cost, the tick's wake latency with and without it, in one run.

    marionette bench console-cost [--segment 10] [--pairs 3] [--priority 80] [--cpu N [--shield] [--share]] [--json FILE] [--strict]

Run it in a terminal (the console draws on stdout). One engine plays the
bundled demo show at half rate in one real-time loop; the run alternates
segments without and with the console (without, with, without, ...), and
the wake-latency histogram of each kind is the sum of the differences of the
engine's histogram at the segment boundaries. docs/console.md has the
numbers. --json FILE also writes the result to FILE as JSON (not to
stdout, where the console draws).

--cpu N pins the tick thread to CPU N and the process's other threads (the
console's among them) off it, unless --share keeps them on it too;
--shield also moves every other task of the machine off CPU N for the run
(marionette/bench/shield.py; root). Without a shield, on a shared machine,
the wake latency's own noise is larger than the console's cost.
Target: the console adds at most CONSOLE_P99_MAX_US to the wake p99.
"""
from __future__ import annotations

import contextlib
import json
import os
import sys
import time
import warnings

import numpy as np

from marionette.bench import STRICT_HELP, exit_status, verdict
from marionette.bench._machine import describe, machine_info
from marionette.bench.shield import pin_off, shield
from marionette.cli.options import Number, output_file
from marionette.config import load_config
from marionette.console import Console
from marionette.demo import DEMO_SHOW
from marionette.engine import Engine
from marionette.errors import ArgumentError
from marionette.show import load_show

CONSOLE_P99_MAX_US = 20.0        # the console's most cost on the wake p99 [us] (issue 17)


def quantile_us(lower, width, counts, q: float) -> float:
    """The q quantile of a histogram [us] (the middle of its bucket)."""
    cum = np.cumsum(counts.astype(np.float64))
    if not cum[-1]:
        return float("nan")
    i = int(np.searchsorted(cum, q * cum[-1]))
    return float(lower[i] + width[i] / 2) / 1e3


def register(sub) -> None:
    p = sub.add_parser("console-cost", help="the live console's cost on the tick's wake latency",
                       description=__doc__.split("\n\n")[0])
    p.add_argument("--segment", type=Number(float, 1.0), default=10.0, metavar="S",
                   help="length of one segment [s]")
    p.add_argument("--pairs", type=Number(int, 1), default=3, metavar="N",
                   help="pairs of segments (without, with)")
    p.add_argument("--priority", type=Number(int, 1, 99), default=80, metavar="P",
                   help="SCHED_FIFO priority of the tick (refused without the right: then SCHED_OTHER)")
    p.add_argument("--cpu", type=Number(int, 0, (os.cpu_count() or 1) - 1), default=None, metavar="N",
                   help="pin the tick thread to CPU N, the process's other threads off it")
    p.add_argument("--shield", action="store_true",
                   help="with --cpu: move every other task of the machine off CPU N for the run (root, cpuset)")
    p.add_argument("--share", action="store_true",
                   help="with --cpu: the console's thread on CPU N too (its cost when the tick shares its CPU)")
    p.add_argument("--json", type=output_file, metavar="FILE",
                   help="also write the result to FILE as JSON (stdout is the console's)")
    p.add_argument("--strict", action="store_true", help=STRICT_HELP)


def run(args) -> int:
    if (args.shield or args.share) and args.cpu is None:
        raise ArgumentError("bench console-cost: --shield and --share need --cpu N")
    if not sys.stdout.isatty():
        raise ArgumentError("bench console-cost: run it in a terminal (the console draws on stdout)")
    with shield(args.cpu) if args.shield else contextlib.nullcontext() as shielded:
        out = collect(args.segment, args.pairs, args.priority, args.cpu, args.share)
    out["shield"] = shielded
    out["targets"] = {"p99_change": out["p99_change_us"] <= CONSOLE_P99_MAX_US}
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=2)
    print(describe(out["machine"]))
    where = ("tick not pinned" if args.cpu is None else
             f"tick on CPU {args.cpu}, console {'on it too' if args.share else 'off it'}"
             + (f", shielded ({shielded['moved']} tasks moved off, {shielded['stayed']} stayed)"
                if shielded else ", not shielded"))
    print(f"{where}; SCHED_FIFO {out['fifo']}; overruns {out['overruns']}")
    for kind in ("without", "with"):
        o = out[kind]
        print(f"{kind:>8} console: {o['ticks']} ticks, wake p50 {o['p50_us']:.1f} us, "
              f"p99 {o['p99_us']:.1f} us, p99.9 {o['p99.9_us']:.1f} us, max {o['max_us']:.1f} us")
    print("segments, p99 [us]: " + ", ".join(f"{k} {v:.1f}" for k, v in out["segments_p99_us"]))
    print(f"p99 change {out['p99_change_us']:+.1f} us (target <= {CONSOLE_P99_MAX_US:g}): "
          f"{verdict(out['targets']['p99_change'])}")
    return exit_status(out["targets"].values(), args.strict)


def collect(segment: float, pairs: int, priority: int, cpu: int | None = None, share: bool = False) -> dict:
    """Wake latency [us] in alternating segments without and with the console drawing."""
    config = load_config(None)
    show = load_show(DEMO_SHOW, config)
    machine = machine_info()                               # before pin_off narrows the usable CPUs
    if cpu is not None and not share:
        pin_off(cpu)
    sums = {"without": None, "with": None}
    segments = []                                          # (kind, its p99 [us])
    with Engine(config, show, record=True, rate=0.5) as engine:
        with warnings.catch_warnings(record=True) as refused:
            warnings.simplefilter("always", RuntimeWarning)
            report = engine.start(priority=priority, cpu=cpu)
        time.sleep(1.0)                                    # settle
        lower, width, _, _ = engine.histogram("wake")      # bucket edges, the same on every call
        for _ in range(pairs):
            for kind in ("without", "with"):
                # the segment counts the ticks while the console draws, not its start and close
                view = Console(engine, True, "console_cost") if kind == "with" else None
                try:
                    before = engine.histogram("wake")[2]
                    time.sleep(segment)
                    after = engine.histogram("wake")[2]
                finally:
                    if view is not None:
                        view.close()
                part = after.astype(np.int64) - before.astype(np.int64)
                sums[kind] = part if sums[kind] is None else sums[kind] + part
                segments.append((kind, round(quantile_us(lower, width, part, 0.99), 1)))
        stats = engine.stats()
    out = {"machine": machine, "segment_s": segment, "pairs": pairs, "fifo": bool(report["fifo"]),
           "priority": priority if report["fifo"] else 0, "cpu": cpu, "share": share,
           "overruns": stats["overruns"], "refused": [str(w.message) for w in refused],
           "segments_p99_us": segments}
    for kind, counts in sums.items():
        top = int(np.nonzero(counts)[0][-1]) if counts.any() else 0
        out[kind] = {"ticks": int(counts.sum()),
                     **{f"p{q * 100:g}_us": round(quantile_us(lower, width, counts, q), 1)
                        for q in (0.5, 0.99, 0.999)},
                     "max_us": round(float(lower[top] + width[top]) / 1e3, 1)}   # its bucket's top
    out["p99_change_us"] = round(out["with"]["p99_us"] - out["without"]["p99_us"], 1)
    return out


def main(argv=None) -> int:
    """``python -m marionette.bench.console_cost``: as ``marionette bench console-cost``."""
    from marionette.cli import main as cli_main
    return cli_main(["bench", "console-cost", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
