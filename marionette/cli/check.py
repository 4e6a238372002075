"""``marionette check [SHOW] [--config FIGURE.toml]``: validate a figure and a show."""
from __future__ import annotations

from marionette.cli.options import figure_and_show, figure_args


def register(sub) -> None:
    p = sub.add_parser("check", help="validate a figure and a show")
    figure_args(p)
    p.set_defaults(run=run)


def run(args) -> int:
    config, show = figure_and_show(args)
    print(f"{config.source}: {config.name}, {len(config.axes)} axes, tick {config.tick_period * 1e3:g} ms")
    print(f"{show.path}: {show.n_ticks} ticks ({show.duration:.2f} s), music {show.music or '-'}")
    for change in show.changes:
        print(f"  changed: {change}")
    return 0
