"""``marionette bench console-cost``: the live console's cost, the tick's wake latency with and without it, in one run.

    marionette bench console-cost [--segment 10] [--pairs 2] [--priority 80] [--json FILE]

Run it in a terminal (the console draws on stdout). One engine plays the
bundled demo show at half rate in one real-time loop; the run alternates
segments without and with the console (without, with, without, ...), and
the wake-latency histogram of each kind is the sum of the differences of the
engine's histogram at the segment boundaries. docs/console.md has the
numbers. --json FILE also writes the result to FILE as JSON (not to
stdout, where the console draws). No target: on a shared machine the wake latency's own noise is
larger than the console's cost (docs/console.md).
"""
from __future__ import annotations

import json
import sys
import time
import warnings

import numpy as np

from marionette.bench._machine import describe, machine_info
from marionette.cli.options import Number, output_file
from marionette.config import load_config
from marionette.console import Console
from marionette.demo import DEMO_SHOW
from marionette.engine import Engine
from marionette.errors import ArgumentError
from marionette.show import load_show


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
    p.add_argument("--pairs", type=Number(int, 1), default=2, metavar="N",
                   help="pairs of segments (without, with)")
    p.add_argument("--priority", type=Number(int, 1, 99), default=80, metavar="P",
                   help="SCHED_FIFO priority of the tick (refused without the right: then SCHED_OTHER)")
    p.add_argument("--json", type=output_file, metavar="FILE",
                   help="also write the result to FILE as JSON (stdout is the console's)")


def run(args) -> int:
    if not sys.stdout.isatty():
        raise ArgumentError("bench console-cost: run it in a terminal (the console draws on stdout)")
    config = load_config(None)
    show = load_show(DEMO_SHOW, config)
    sums = {"without": None, "with": None}
    segments = []                                          # (kind, its p99 [us])
    with Engine(config, show, record=True, rate=0.5) as engine:
        with warnings.catch_warnings(record=True) as refused:
            warnings.simplefilter("always", RuntimeWarning)
            report = engine.start(priority=args.priority)
        time.sleep(1.0)                                    # settle
        lower, width, before, _ = engine.histogram("wake")
        for _ in range(args.pairs):
            for kind in ("without", "with"):
                view = Console(engine, True, "console_cost") if kind == "with" else None
                try:
                    time.sleep(args.segment)
                finally:
                    if view is not None:
                        view.close()
                _, _, after, _ = engine.histogram("wake")
                part = after.astype(np.int64) - before.astype(np.int64)
                sums[kind] = part if sums[kind] is None else sums[kind] + part
                segments.append((kind, round(quantile_us(lower, width, part, 0.99), 1)))
                before = after
        stats = engine.stats()
    out = {"machine": machine_info(), "segment_s": args.segment, "pairs": args.pairs, "fifo": bool(report["fifo"]),
           "priority": args.priority if report["fifo"] else 0, "overruns": stats["overruns"],
           "refused": [str(w.message) for w in refused], "segments_p99_us": segments}
    for kind, counts in sums.items():
        out[kind] = {"ticks": int(counts.sum()),
                     **{f"p{q * 100:g}_us": round(quantile_us(lower, width, counts, q), 1)
                        for q in (0.5, 0.99, 0.999)}}
    out["p99_change_us"] = round(out["with"]["p99_us"] - out["without"]["p99_us"], 1)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=2)
    print(f"machine: {describe(out['machine'])}")
    for kind in ("without", "with"):
        o = out[kind]
        print(f"{kind:>8} console: {o['ticks']} ticks, wake p50 {o['p50_us']:.1f} us, "
              f"p99 {o['p99_us']:.1f} us, p99.9 {o['p99.9_us']:.1f} us")
    print("segments, p99 [us]: " + ", ".join(f"{k} {v:.1f}" for k, v in segments))
    print(f"p99 change {out['p99_change_us']:+.1f} us; SCHED_FIFO {out['fifo']}; "
          f"overruns {out['overruns']}")
    return 0


def main(argv=None) -> int:
    """``python -m marionette.bench.console_cost``: as ``marionette bench console-cost``."""
    from marionette.cli import main as cli_main
    return cli_main(["bench", "console-cost", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
