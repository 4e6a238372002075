"""``marionette bench NAME``: the benchmarks; each one's options and report
are in its module (marionette/bench/NAME.py: register, run, collect)."""
from __future__ import annotations

from marionette.bench import bands, console_cost, fuzz, jitter, led_sets, link, misses, moves, shape, sync, tick

BENCHES = {"tick": tick, "jitter": jitter, "moves": moves, "fuzz": fuzz, "link": link, "sync": sync,
           "bands": bands, "led-sets": led_sets, "shape": shape, "console-cost": console_cost,
           "misses": misses}


def register(sub) -> None:
    p = sub.add_parser("bench", help="benchmarks: " + ", ".join(BENCHES),
                       description="Benchmarks of the engine, the links and the music follower.")
    benches = p.add_subparsers(dest="bench", required=True, metavar="BENCH")
    for module in BENCHES.values():
        module.register(benches)
    p.set_defaults(run=run)


def run(args) -> int:
    return BENCHES[args.bench].run(args)
