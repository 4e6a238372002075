"""The ``marionette`` command.

    marionette play [SHOW] [--config FIGURE.toml] [--realtime] [--link ...] [--music ...]
    marionette check | shape | calibrate | teach | plot | sim | sync-sim | log | demo ...
    marionette bench tick|jitter|moves|fuzz|link|sync [...]

One module per command (marionette/cli/<command>.py), each with
``register(subparsers)``, which adds its parser and sets ``run``, and
``run(args)``, which returns the exit status.
"""
from __future__ import annotations

import argparse
import sys

from marionette.cli import (bench, calibrate, check, demo, log, play, plot, shape, sim, sync_sim,
                            teach)
from marionette.errors import MarionetteError

COMMANDS = (play, check, shape, calibrate, teach, plot, sim, sync_sim, log, demo, bench)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="marionette", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = build_parser().parse_args(argv)
    try:
        return args.run(args)
    except MarionetteError as exc:
        print(f"marionette: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:      # outside a show (a show's own Ctrl-C: marionette.console)
        print("marionette: interrupted", file=sys.stderr)
        return 130
