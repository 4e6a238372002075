"""Options that more than one command takes, and the argparse types that
check a value when it is parsed: a number in its range, a file to read, a
file (or an image) to write. A refused value is argparse's error, which
names the option and the value (exit status 2)."""
from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

from marionette.config import load_config
from marionette.demo import DEMO_SHOW
from marionette.show import LIMIT_POLICIES, MIN_COMPRESS_GAIN, load_show


class Number:
    """argparse type: an int or a float in a range; NaN and infinities are
    refused. low/high None: unbounded; above: the low end excluded. The
    range is in `range` (for the help, and for tests that try values outside)."""

    def __init__(self, kind=float, low=None, high=None, *, above: bool = False):
        self.kind, self.low, self.high, self.above = kind, low, high, above
        self.__name__ = "whole number" if kind is int else "number"   # argparse's "invalid ..."

    @property
    def range(self) -> str:
        low, high = (v if v is None or self.kind is int else f"{v:g}" for v in (self.low, self.high))
        if self.low is not None and self.high is not None:
            return f"{'(' if self.above else '['}{low}, {high}]"
        if self.low is not None:
            return f"{'>' if self.above else '>='} {low}"
        return f"<= {high}" if self.high is not None else "any"

    def __call__(self, text: str):
        try:
            value = self.kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a {self.__name__}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
        if ((self.low is not None and (value <= self.low if self.above else value < self.low))
                or (self.high is not None and value > self.high)):
            raise argparse.ArgumentTypeError(f"{text!r} is outside its range {self.range}")
        return value


CONFIG_HELP = "figure TOML; default: the bundled Hoffmann 1996 figure"
ACCEL_FRACTION = Number(float, 0.0, 1.0, above=True)   # of each top acceleration (shape, teach)
PRIORITY = Number(int, 0, 99)                          # SCHED_FIFO; 0: normal
SEED = Number(int, 0, 2**63 - 1)


class HelpFormatter(argparse.HelpFormatter):
    """Every numeric option's help says its range (when it does not already)."""

    def _get_help_string(self, action):
        text = super()._get_help_string(action) or ""
        if isinstance(action.type, Number) and action.type.range not in text:
            text = f"{text} (range {action.type.range})".strip()
        return text


def input_file(text: str) -> str:
    """argparse type: a file that exists and can be read (what is in it is
    the reader's to check, with the line and value at fault)."""
    path = Path(text)
    if not path.exists():
        raise argparse.ArgumentTypeError(f"{text}: no such file")
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: a folder, not a file")
    if not os.access(path, os.R_OK):
        raise argparse.ArgumentTypeError(f"{text}: no permission to read it")
    return text


def output_file(text: str) -> str:
    """argparse type: a file that can be written (its folder exists and is
    writable; an existing file or device is writable), so that a run does
    not end in an error after its work is done."""
    if not text:
        raise argparse.ArgumentTypeError("an empty path")
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: a folder, not a file")
    if path.exists():
        if not os.access(path, os.W_OK):
            raise argparse.ArgumentTypeError(f"{text}: no permission to write it")
        return text
    folder = path.parent
    if not folder.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: the folder {folder} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"{text}: no permission to write in {folder}")
    return text


def image_file(text: str) -> str:
    """argparse type: an output_file whose suffix is an image format that
    matplotlib writes (.png, .pdf, .svg, ...)."""
    output_file(text)
    try:
        from matplotlib.backend_bases import FigureCanvasBase
    except ImportError:                 # said by the command that needs it
        return text
    formats = FigureCanvasBase.get_supported_filetypes()
    if Path(text).suffix.lower().lstrip(".") not in formats:
        raise argparse.ArgumentTypeError(
            f"{text}: unknown image format {Path(text).suffix or '(no suffix)'!r} "
            f"(use one of {', '.join('.' + f for f in sorted(formats))})")
    return text


def figure_args(p) -> None:
    """SHOW, --config and --on-limits (play, check)."""
    p.add_argument("show", nargs="?", type=input_file,
                   help="show file (.csv or .npz); default: the bundled demo")
    p.add_argument("--config", type=input_file, help=CONFIG_HELP)
    p.add_argument("--on-limits", choices=LIMIT_POLICIES, default="error",
                   help="taught positions outside an axis's limits: error (default), clamp "
                        "(cut to the limit) or compress (scale the axis into its limits; refused "
                        f"under a gain of {MIN_COMPRESS_GAIN:g})")


def figure_and_show(args):
    """The figure and the show that figure_args named."""
    config = load_config(args.config)
    show = load_show(args.show or DEMO_SHOW, config, on_limits=args.on_limits)
    return config, show
