"""LED sets lost to dropped detections in the teach-in (docs/teach.md, Strobe timing).

    marionette bench led-sets [--seeds N] [--duration S]

The teach simulator's dance (marionette.teach.synthetic, no shading, so that only
single detections are lost) is observed by the two default cameras, each detection
dropped with the given probability; the recording goes through triangulation and
set alignment as in `marionette teach`, and a set is lost when two or more of its
LEDs are missing (one is complemented). Prints the share of sets lost per dropout
rate, over fixed seeds, without and with the bridging across one lost sample.
"""
from __future__ import annotations

import sys

import numpy as np

from marionette.cli.options import Number
from marionette.teach.filters import complement_missing_led
from marionette.teach.pipeline import led_points
from marionette.teach.rucksack import align_to_set_times
from marionette.teach.synthetic import synthetic_recording

DROPOUTS = (0.02, 0.05)      # probabilities that one detection is lost [1]


def lost_set_share(dropout: float, seeds, duration: float = 60.0, **align) -> float:
    """Share of LED sets with two or more LEDs missing [1], over recordings of
    ``duration`` [s] made with each seed; ``align``: options of align_to_set_times."""
    lost = total = 0
    for seed in seeds:
        syn = synthetic_recording(seed, duration, dropout=dropout, shade_rate=0.0)
        pts = led_points(syn.recording, syn.cameras)
        _, sets = align_to_set_times(pts.times, pts.leds, pts.points, half_side=syn.b, **align)
        _, n_missing = complement_missing_led(sets)
        lost += int(np.sum(n_missing >= 2))
        total += n_missing.size
    return lost / total


def register(sub) -> None:
    parser = sub.add_parser("led-sets", help="LED sets lost to dropped detections, with and without bridging",
                            description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=Number(int, 1), default=10, metavar="N",
                        help="recordings per dropout rate (seeds 1..N)")
    parser.add_argument("--duration", type=Number(float, 1.0), default=60.0, metavar="S",
                        help="[s] of each recording")


def run(args) -> int:
    seeds = range(1, args.seeds + 1)
    print(f"LED sets lost, {args.seeds} recordings of {args.duration:g} s each:")
    for dropout in DROPOUTS:
        before = lost_set_share(dropout, seeds, args.duration, max_bridge=0.0)
        after = lost_set_share(dropout, seeds, args.duration)
        print(f"  dropped detections {dropout:.0%}: {before:.2%} without bridging, {after:.2%} with it")
    return 0


def main(argv=None) -> int:
    """``python -m marionette.bench.led_sets``: as ``marionette bench led-sets``."""
    from marionette.cli import main as cli_main
    return cli_main(["bench", "led-sets", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
