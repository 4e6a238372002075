"""The ``marionette`` command.

    marionette play [SHOW] [--config FIGURE.toml] [--realtime] [--link ...] [--music ...]
    marionette check | shape | calibrate | teach | plot | sim | sync-sim | log | demo | conformance ...
    marionette bench tick|jitter|moves|fuzz|link|sync [...]

One module per command (marionette/cli/<command>.py), each with
``register(subparsers)``, which adds its parser and sets ``run``, and
``run(args)``, which returns the exit status.
"""
from __future__ import annotations

import argparse
import importlib
import sys

from marionette import __version__
from marionette.cli.options import HelpFormatter
from marionette.errors import MarionetteError

DESCRIPTION = """Show control for a servo-driven marionette: it plays a taught motion in
step with music. A C engine runs the 20 ms tick in real time and sends each
servo its setpoint ahead by the servo's dead time and lag.

Start with 'marionette demo' (the bundled figure and sample dance on simulated
servo nodes); teach a dance with calibrate and teach, play it with play, check
a figure and a show with check. 'marionette COMMAND --help' tells more; the
documentation is in docs/ and README.md."""

# the commands' modules under marionette/cli/, imported when the parser is
# built: a module that imports marionette.cli.options (the benches do) does
# not pull every command in with it
COMMANDS = ("play", "check", "shape", "calibrate", "teach", "plot", "sim", "sync_sim", "log", "demo",
            "conformance", "bench")


class TopHelpFormatter(HelpFormatter, argparse.RawDescriptionHelpFormatter):
    """The top-level description keeps its paragraphs."""


class Parser(argparse.ArgumentParser):
    """argparse's parser, whose error is one line and a pointer to --help
    (not the whole usage, which for play is a dozen lines), and whose help
    gives each number's range."""

    def __init__(self, *args, formatter_class=HelpFormatter, **kwargs):
        super().__init__(*args, formatter_class=formatter_class, **kwargs)

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The parser of every command; given the command line, of its command
    alone when it names one (so `marionette sim`, the simulator process,
    loads neither the engine nor the other commands)."""
    parser = Parser(prog="marionette", description=DESCRIPTION, formatter_class=TopHelpFormatter)
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    named = [m for m in COMMANDS if argv and argv[0] == m.replace("_", "-")]
    for name in named or COMMANDS:
        importlib.import_module(f"marionette.cli.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    try:
        args = build_parser(argv).parse_args(argv)
    except SystemExit as exc:      # --help, --version, or argparse's one-line error
        return exc.code
    try:
        return args.run(args)
    except MarionetteError as exc:
        print(f"marionette: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:          # a file named on the command line, opened where it is used
        if exc.filename is None:
            raise
        print(f"marionette: error: {exc.filename}: {exc.strerror}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:      # outside a show (a show's own Ctrl-C: marionette.console)
        print("marionette: interrupted", file=sys.stderr)
        return 130
