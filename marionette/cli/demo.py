"""``marionette demo [--headless] [--duration S]``: the whole system in one command.

On the bundled figure and teach-in sample: teaches the sample's show
(``calibrate --sample`` and ``teach --sample``, about a second, into a
temporary directory), starts the simulated servo nodes in their own process
(``marionette sim --serial``, on a pty), plays the taught show in real time
through that pty under the live console, following the sample's music played
back as if live (``play --realtime --link serial:PTY --music music.wav``),
then prints play's summary and the simulator's (its watchdog trips among
them). The simulator is stopped on every way out: the end of the show,
Ctrl-C, an error; and if this process is killed, the kernel sends it
SIGTERM (PR_SET_PDEATHSIG). docs/console.md, "marionette demo".
"""
from __future__ import annotations

import contextlib
import io
import json
import os
import select
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from marionette.cli.options import Number
from marionette.errors import MarionetteError

DEFAULT_DURATION = 20.0  # [s] of show: the intro, a verse and into the chorus; CI runs it
READY_TIMEOUT = 30.0     # the simulator's ready line, on a loaded machine [s]
QUIT_TIMEOUT = 20.0      # its summary after 'quit' [s]
SIM_PRIORITY = 30        # SCHED_FIFO when permitted, below the engine's 80 (as the HIL tests)
AFTER_SHOW = 0.3         # [s] before 'quit': longer than a node's watchdog (5 ticks), so a
                         # show's end that did not tell the nodes shows as trips


def register(sub) -> None:
    p = sub.add_parser("demo", help="teach the bundled sample, play it on simulated servo nodes "
                                    "with its music under the live console, print the summaries",
                       description=__doc__.split("\n\n")[1].replace("\n", " "))
    p.add_argument("--duration", type=Number(float, 0.0, above=True), default=DEFAULT_DURATION,
                   help=f"seconds of show to play (default {DEFAULT_DURATION:g}; the sample's "
                        "whole song: 45)")
    p.add_argument("--headless", action="store_true",
                   help="no live console: one status line per second on stderr (also whenever "
                        "stdout is not a terminal)")
    p.add_argument("--json", action="store_true", help="the status lines as JSON lines (headless)")
    p.set_defaults(run=run)


def teach_sample(directory: Path) -> Path:
    """The sample's taught show, made as `calibrate --sample` and `teach
    --sample` make it (their reports kept quiet); its path."""
    from marionette.cli import build_parser
    cameras, show = directory / "cameras.toml", directory / "sample_show.npz"
    parser = build_parser()
    for argv in (["calibrate", "--sample", "-o", str(cameras)],
                 ["teach", "--sample", "--cameras", str(cameras), "-o", str(show), "--quiet"]):
        args = parser.parse_args(argv)
        with contextlib.redirect_stdout(io.StringIO()):
            status = args.run(args)
        if status:
            raise MarionetteError(f"demo: `marionette {' '.join(argv[:2])}` failed ({status})")
    return show


def _die_with_parent() -> None:          # in the child, before exec (Linux)
    import ctypes
    PR_SET_PDEATHSIG = 1
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
    except (OSError, AttributeError):
        pass


class Simulator:
    """`marionette sim --serial` in its own process and session (a Ctrl-C
    on the terminal reaches the demo only, which then stops the show first
    and the simulator after it), with a pipe to its control stdin."""

    def __init__(self, log):
        parent = os.getpid()

        def setup() -> None:
            if sys.platform.startswith("linux"):
                _die_with_parent()
            if os.getppid() != parent:     # the demo died before that took hold
                os._exit(1)

        self.log = log
        self.proc = subprocess.Popen(
            # -P: not the working directory first on sys.path (a source checkout there
            # would shadow the installed package, whose extensions are built)
            [sys.executable, "-P", "-m", "marionette.cli", "sim", "--serial", "--priority", str(SIM_PRIORITY)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log, text=True,
            start_new_session=True, preexec_fn=setup)
        self.summary: dict | None = None
        try:
            ready = self._line(READY_TIMEOUT)
            if not ready.get("ready") or "serial" not in ready:
                raise MarionetteError(f"demo: the simulator said {ready!r}, not where to connect")
            self.path = ready["serial"]
        except BaseException:
            self.close()
            raise

    @property
    def pid(self) -> int:
        return self.proc.pid

    def _line(self, timeout: float) -> dict:
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout)
        line = self.proc.stdout.readline() if ready else ""
        if not line:
            raise MarionetteError("demo: the simulator " + ("ended" if ready else
                                  f"did not answer within {timeout:g} s") + self.stderr_text())
        return json.loads(line)

    def stderr_text(self) -> str:
        self.log.flush()
        self.log.seek(0)
        text = self.log.read().strip()
        return f": {text}" if text else ""

    def close(self) -> dict | None:
        """'quit', then its summary; SIGTERM, then SIGKILL if it will not go.
        The process is reaped whatever happens here (Ctrl-C included)."""
        if self.proc.returncode is not None:
            return self.summary
        try:
            try:
                self.proc.stdin.write("quit\n")
                self.proc.stdin.flush()
            except (OSError, ValueError):
                pass
            try:
                out, _ = self.proc.communicate(timeout=QUIT_TIMEOUT)
            except subprocess.TimeoutExpired:
                self.proc.terminate()                     # SIGTERM: it still writes its summary
                out, _ = self.proc.communicate(timeout=QUIT_TIMEOUT)
            for line in reversed(out.strip().splitlines()):
                if line.startswith('{"summary"'):
                    self.summary = json.loads(line)["summary"]
                    break
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()
        return self.summary


def summary_lines(summary: dict | None, pid: int) -> list[str]:
    """The simulator's summary in a few lines, ending with its watchdog trips."""
    if summary is None:
        return [f"simulator (pid {pid}): ended without a summary"]
    link = summary["link"]
    errors = sum(v for k, v in link.items() if k not in ("bytes", "frames_ok"))
    nodes = summary["nodes"]
    lines = [f"simulator (marionette sim --serial, pid {pid}): {summary['messages']} messages, "
             f"{link['frames_ok']} frames ok, {errors} frame errors"]
    for n, c in nodes.items():
        lines.append(f"  node {n}: {c['setpoints']} setpoints, {c['seq_gaps']} sequence gaps, "
                     f"{c['clamped']} clamped, {c['stale']} stale, {c['ignored_estop']} ignored "
                     f"in e-stop, {c['watchdog_trips']} watchdog trips")
    trips = sum(c["watchdog_trips"] for c in nodes.values())
    lines.append(f"  watchdog trips: {trips}")
    return lines


def _terminated(signum, frame):
    raise SystemExit(128 + signum)        # 143: the finally clauses stop the simulator


def run(args) -> int:
    if threading.current_thread() is not threading.main_thread():
        return _demo(args)
    old = signal.signal(signal.SIGTERM, _terminated)  # play's view takes it over during the show
    try:
        return _demo(args)
    finally:
        signal.signal(signal.SIGTERM, old)


def _demo(args) -> int:
    from marionette.cli import build_parser, play
    from marionette.config import load_config
    from marionette.teach.make_sample import sample_path
    period = load_config(None).tick_period                            # [s]
    ticks = max(1, round(args.duration / period))
    with tempfile.TemporaryDirectory(prefix="marionette-demo-") as tmp:
        t0 = time.monotonic()
        show = teach_sample(Path(tmp))
        print(f"demo: taught the bundled sample (calibrate --sample, teach --sample) in "
              f"{time.monotonic() - t0:.1f} s", flush=True)
        with open(Path(tmp) / "sim.log", "w+") as log:
            sim = None
            try:
                sim = Simulator(log)
                print(f"demo: simulated servo nodes (marionette sim --serial, pid {sim.pid}) "
                      f"on {sim.path}", flush=True)
                argv = ["play", str(show), "--realtime", "--link", f"serial:{sim.path}",
                        "--music", str(sample_path("music.wav")), "--ticks", str(ticks)]
                argv += ["--headless"] * args.headless + ["--json"] * args.json
                print(f"demo: play --realtime --link serial:{sim.path} --music SAMPLE/music.wav "
                      f"--ticks {ticks} ({ticks * period:g} s of show)", flush=True)
                status = play.run(build_parser().parse_args(argv))
                time.sleep(AFTER_SHOW)
            finally:
                if sim is not None:
                    summary = sim.close()
                    for line in summary_lines(summary, sim.pid):
                        print(line, flush=True)
                    text = sim.stderr_text()
                    if text:
                        print(f"  simulator's stderr{text}", file=sys.stderr, flush=True)
    return status if summary is not None else (status or 1)
