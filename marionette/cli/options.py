"""Options that more than one command takes."""
from __future__ import annotations

from marionette.config import load_config
from marionette.demo import DEMO_SHOW
from marionette.show import LIMIT_POLICIES, load_show


def figure_args(p) -> None:
    """SHOW, --config and --on-limits (play, check)."""
    p.add_argument("show", nargs="?", help="show file (.csv or .npz); default: the bundled demo")
    p.add_argument("--config", help="figure TOML; default: the bundled Hoffmann 1996 figure")
    p.add_argument("--on-limits", choices=LIMIT_POLICIES, default="error",
                   help="what to do with taught positions outside an axis's limits")


def figure_and_show(args):
    """The figure and the show that figure_args named."""
    config = load_config(args.config)
    show = load_show(args.show or DEMO_SHOW, config, on_limits=args.on_limits)
    return config, show
