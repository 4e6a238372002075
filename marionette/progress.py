"""A one-line progress bar on stderr for the offline tools.

    progress = Progress(["read", "triangulate", "filter"], enabled=not args.quiet)
    progress.step("read")          # [#####...............] 1/3 read
    ...
    progress.done()                # clears the line

It draws only when enabled and the stream is a terminal, so pipes, logs and tests see
nothing. Progress is counted in named steps, not time.
"""
from __future__ import annotations

import sys
from typing import Sequence, TextIO

WIDTH = 24   # bar length [characters]


class Progress:
    """Named steps drawn as ``[####....] k/n name`` on one rewritten line."""

    def __init__(self, steps: Sequence[str], enabled: bool = True, stream: TextIO | None = None):
        self.steps = list(steps)
        self.stream = sys.stderr if stream is None else stream
        isatty = getattr(self.stream, "isatty", None)
        self.enabled = bool(enabled and isatty is not None and isatty())
        self.count = 0
        self._shown = 0           # length of the line on screen [characters]

    def step(self, name: str) -> None:
        """Mark the start of step ``name`` (one of the steps given, in any order)."""
        self.count = min(self.count + 1, len(self.steps))
        if not self.enabled:
            return
        filled = WIDTH * self.count // max(len(self.steps), 1)
        line = f"[{'#' * filled}{'.' * (WIDTH - filled)}] {self.count}/{len(self.steps)} {name}"
        self.stream.write("\r" + line.ljust(self._shown))
        self.stream.flush()
        self._shown = len(line)

    def done(self) -> None:
        """Erase the bar (so the report that follows starts on a clean line)."""
        if self.enabled and self._shown:
            self.stream.write("\r" + " " * self._shown + "\r")
            self.stream.flush()
            self._shown = 0
