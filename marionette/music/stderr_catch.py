"""Keep a C library's own error lines off the process's stderr.

PortAudio's ALSA host API (and ALSA's plugins under it) write their
complaints straight to file descriptor 2 with fprintf, e.g.

    Expression 'PaAlsaStream_WaitForFrames( stream, &framesAvail, &xrun )' failed in
    'src/hostapi/alsa/pa_linux_alsa.c', line: 4285

There is no hook for them in the library the distributions ship, so the only
place to catch them is the descriptor. While at least one holder is
registered, fd 2 is a pipe read by a relay thread: a line that looks like
such library text (LIBRARY_LINE) goes to the holders' `on_line(line)` and
not to the terminal; every other line (Python's own stderr writes,
tracebacks, other libraries) is passed on to the real stderr unchanged, in
order. The last holder to leave puts the real stderr back.

    catcher = StderrCatcher.shared()
    catcher.add(listener)          # listener(line: str)
    ...
    catcher.remove(listener)       # the last one restores fd 2
"""
from __future__ import annotations

import os
import re
import select
import sys
import threading
from typing import Callable

# PortAudio's failed-expression and assertion reports, its host API's own
# messages, and ALSA library lines ("ALSA lib pcm.c:...")
LIBRARY_LINE = re.compile(r"^(Expression '.*' failed in '|PaAlsa|PaUnixThread|ALSA lib |"
                          r"Assertion '.*' failed in '|.*\bpa_linux_alsa\.c\b)")
PARTIAL_WAIT = 0.05         # a line without its newline yet is passed on after this [s]


class StderrCatcher:
    _shared: "StderrCatcher | None" = None
    _shared_lock = threading.Lock()

    @classmethod
    def shared(cls) -> "StderrCatcher":
        """The process's one catcher (fd 2 exists once)."""
        with cls._shared_lock:
            if cls._shared is None:
                cls._shared = cls()
            return cls._shared

    def __init__(self):
        self._lock = threading.Lock()          # the listeners (the relay takes it too)
        self._fd_lock = threading.Lock()       # redirecting and restoring fd 2
        self._listeners: list[Callable[[str], object]] = []
        self._saved_fd: int | None = None       # the real stderr while caught
        self._thread: threading.Thread | None = None

    def add(self, listener: Callable[[str], object]) -> None:
        with self._fd_lock:
            with self._lock:
                self._listeners.append(listener)
            if self._saved_fd is None:
                self._start()

    def remove(self, listener: Callable[[str], object]) -> None:
        with self._fd_lock:
            with self._lock:
                if listener in self._listeners:
                    self._listeners.remove(listener)
                last = not self._listeners
            if last and self._saved_fd is not None:
                self._stop()

    def _start(self) -> None:
        _flush_python_stderr()
        read_fd, write_fd = os.pipe()
        self._saved_fd = os.dup(2)
        os.dup2(write_fd, 2)
        os.close(write_fd)                     # fd 2 is now the pipe's only writer
        self._thread = threading.Thread(target=self._relay, args=(read_fd, self._saved_fd),
                                        name="stderr-catch", daemon=True)
        self._thread.start()

    def _stop(self) -> None:
        _flush_python_stderr()
        saved, thread = self._saved_fd, self._thread
        os.dup2(saved, 2)                      # closes the pipe's writer: the relay reads EOF
        thread.join(timeout=2.0)
        os.close(saved)
        self._saved_fd = self._thread = None

    def _relay(self, read_fd: int, out_fd: int) -> None:
        pending = b""
        try:
            while True:
                ready, _, _ = select.select([read_fd], [], [], PARTIAL_WAIT if pending else None)
                if not ready:                  # a partial line waited long enough: pass it on
                    _write_all(out_fd, pending)
                    pending = b""
                    continue
                chunk = os.read(read_fd, 65536)
                if not chunk:
                    break
                pending += chunk
                *lines, pending = pending.split(b"\n")
                for raw in lines:
                    self._line(raw + b"\n", out_fd)
            if pending:
                self._line(pending, out_fd)
        finally:
            os.close(read_fd)

    def _line(self, raw: bytes, out_fd: int) -> None:
        text = raw.decode("utf-8", "replace").rstrip("\n")
        if LIBRARY_LINE.match(text):
            with self._lock:
                listeners = list(self._listeners)
            for listener in listeners:
                try:
                    listener(text)
                except Exception:              # a listener's fault must not stop the relay
                    pass
        else:
            _write_all(out_fd, raw)


def _flush_python_stderr() -> None:
    try:
        sys.stderr.flush()
    except Exception:
        pass


def _write_all(fd: int, data: bytes) -> None:
    while data:
        try:
            data = data[os.write(fd, data):]
        except OSError:
            return
