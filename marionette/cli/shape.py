"""``marionette shape SHOW -o SHAPED``: join the points of rest by timed
parabolic moves, offline (docs/shaping.md)."""
from __future__ import annotations

from marionette.cli.options import ACCEL_FRACTION, CONFIG_HELP, Number, input_file, output_file
from marionette.config import load_config
from marionette.engine import DEFAULT_LEAD, LEAD_MODES
from marionette.show import load_show


def register(sub) -> None:
    p = sub.add_parser("shape", help="join the points of rest by timed parabolic moves (offline)")
    p.add_argument("show", type=input_file, help="taught show file (.csv or .npz)")
    p.add_argument("-o", "--output", required=True, type=output_file,
                   help="shaped show to write (.csv or .npz)")
    p.add_argument("--config", type=input_file, help=CONFIG_HELP)
    p.add_argument("--policy", choices=("reduce", "borrow", "reject"), default="reduce",
                   help="infeasible moves: reduce the excursion, borrow time from the "
                        "preceding rest, or reject (exit 2)")
    p.add_argument("--prominence", type=Number(float, 0.0, above=True),
                   help="smallest excursion counted as a point of rest [axis unit] "
                        "(default: 2 %% of each axis's range)")
    p.add_argument("--rest-tolerance", type=Number(float, 0.0),
                   help="rest band around an extremum [axis unit] (default: 0.5 %% of the range)")
    p.add_argument("--accel-fraction", type=ACCEL_FRACTION, default=1.0,
                   help=f"plan the moves to this fraction of each top acceleration, {ACCEL_FRACTION.range}")
    p.add_argument("--lead", choices=sorted(LEAD_MODES), default=DEFAULT_LEAD,
                   help="the lead the show will be played with (play --lead): the moves are "
                        "planned for the command it makes (default: %(default)s)")
    p.set_defaults(run=run)


def run(args) -> int:
    from marionette.shape import shape_show
    config = load_config(args.config)
    show = load_show(args.show, config)
    shaped, report = shape_show(show, config, policy=args.policy, prominence=args.prominence,
                                rest_tolerance=args.rest_tolerance,
                                accel_fraction=args.accel_fraction, lead=args.lead)
    shaped.save(args.output)
    print(report)
    print(f"wrote {args.output}")
    return 0
