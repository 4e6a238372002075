"""The live view of ``marionette play``: a full-screen console, status lines, Ctrl-C.

    view = open_view(args, engine)       # Console on a terminal, else Headless
    ...
    view.wait()                          # real time: instead of engine.wait()
    view.step(n)                         # step mode: instead of engine.step(n)
    view.close()                         # the terminal restored (idempotent)
    return status or view.status         # 130 after Ctrl-C

Everything here runs in Python threads that only read the engine
(snapshot(), stats(), engine.nodes) or send it requests (stop_motion(),
estop(), ...), applied by the tick at its next start: the tick thread is
never waited on. The console needs the 'console' extra (rich); without it
play says so in one line and runs headless. docs/console.md.
"""
from __future__ import annotations

import json
import os
import signal
import sys
import threading
import time
from collections import deque

import numpy as np

from marionette import _core, protocol

REFRESH = 0.1            # console refresh interval [s]
STATUS_INTERVAL = 1.0    # headless status line interval [s]
MESSAGES = 4             # stderr lines shown in the console
STRIP = 60               # loudness strip length [samples of REFRESH]
LIMIT_WINDOW = 5.0       # limiter activity shown over this many recent seconds [s]
STOP_TIMEOUT = 10.0      # a controlled stop waits at most this long for rest [s]
STATUS_PREFIX = "status: "  # how a headless text line begins (grep -v '^status: ')
STEP_CHUNK = 25          # step mode: ticks between looks at the keys and the stop [ticks]
BARS = " ▁▂▃▄▅▆▇█"
KEYS = (("space", "pause/resume"), ("e", "e-stop"), ("r", "release"), ("h", "home"),
        ("b", "blend in"), ("q", "stop and quit"))
# key -> (Engine method, paused after it (None: as it was), message); space is
# pause or resume, q a controlled stop (View.controlled_stop)
ACTIONS = {"pause": ("stop_motion", True, "paused: limited stop, holding"),
           "resume": ("blend_in", False, "resumed: blending back in"),
           "e": ("estop", True, "E-STOP: nodes latched, commands ramped to rest"),
           "r": ("release_estop", None, "e-stop released: holding (b blends in)"),
           "h": ("home", True, "homing"),
           "b": ("blend_in", False, "blending in")}
FLAG_NAMES = ((_core.FLAG_LIMITED, "limited"), (_core.FLAG_END, "end"),
              (_core.FLAG_BAD_INPUT, "bad input"), (_core.FLAG_MOVING, "moving"),
              (_core.FLAG_HOLDING, "holding"), (_core.FLAG_UNFOLLOWED, "unfollowed"))
NODE_ALARMS = ((protocol.FLAG_FAULT, "FAULT"), (protocol.FLAG_ESTOP, "ESTOP"),
               (protocol.FLAG_WATCHDOG, "WATCHDOG"), (protocol.FLAG_FOLLOWING, "FOLLOWING"),
               (protocol.FLAG_LIMIT, "limit"))


class RecordTap:
    """What the console takes from every flight record, as the drain thread
    hands them over: the newest live and stored loudness (the snapshot's
    live loudness is NaN in the ticks without a new frame), and limiter
    activity by axis (the records' excess: not 0 where a limit acted)."""

    def __init__(self, config, period: float):
        self.period = period
        self.names = config.axis_names
        self.total = np.zeros(len(self.names), dtype=np.int64)
        self.recent: deque = deque()          # (monotonic time [s], per-axis counts)
        self.limited_ticks = 0                # ticks the engine flagged as limited
        self.loudness: tuple = (None, None)   # newest (live, stored) loudness
        self._lock = threading.Lock()

    def __call__(self, records: np.ndarray) -> None:      # on the drain thread
        counts = (records["excess"] != 0).sum(axis=0)
        live = records["live_loudness"][np.isfinite(records["live_loudness"])]
        with self._lock:
            self.loudness = (float(live[-1]) if len(live) else self.loudness[0],
                             float(records["stored_loudness"][-1]))
            self.total += counts
            self.limited_ticks += int(np.count_nonzero(records["flags"] & _core.FLAG_LIMITED))
            now = time.monotonic()
            self.recent.append((now, counts))
            while self.recent and self.recent[0][0] < now - LIMIT_WINDOW:
                self.recent.popleft()

    def by_axis(self) -> dict:
        """axis -> (ticks limited in the last LIMIT_WINDOW s, in the whole show)."""
        with self._lock:
            recent = sum((c for _, c in self.recent), np.zeros(len(self.names), dtype=np.int64))
            return {n: (int(r), int(t)) for n, r, t in zip(self.names, recent, self.total)}


def gather(engine, period: float, realtime: bool, limits: RecordTap | None = None) -> dict:
    """One status: what the console and the status lines show, as plain values."""
    snap = engine.snapshot()
    stats = engine.stats()
    out = {"time": round(time.time(), 3), "tick": None}
    if snap is not None:
        out.update(tick=snap.tick, show_s=round(snap.position * period, 3),
                   position=round(snap.position, 2), rate=round(snap.rate, 4),
                   flags=[name for bit, name in FLAG_NAMES if snap.flags & bit],
                   follow_state=snap.follow_state,
                   follow_confidence=None if np.isnan(snap.follow_confidence)
                   else round(snap.follow_confidence, 3),
                   live_loudness=None if np.isnan(snap.live_loudness) else round(snap.live_loudness, 4),
                   stored_loudness=round(snap.stored_loudness, 4))
    out["show_total_s"] = round((engine.show.n_ticks - 1) * period, 3)
    out["wake_p99_us"] = round(stats["wake"]["p99_us"], 1) if realtime else None
    out["overruns"] = stats["overruns"]
    out["limited_axis_ticks"] = stats["limited"]
    if limits is not None:
        out["limited_by_axis"] = {n: r for n, (r, _) in limits.by_axis().items() if r}
    recorded = stats.get("recorded", 0)
    pending = max(0, stats["ticks"] - recorded - stats["records_dropped"])
    out["recorder"] = {"records": recorded, "dropped": stats["records_dropped"],
                       "ring_fill": round(pending / engine_slots(), 3)}
    if engine.nodes is not None:
        out["nodes"] = node_states(engine, snap, period if realtime else None)
    return out


def engine_slots() -> int:
    from marionette.engine import RECORD_SLOTS
    return RECORD_SLOTS


def node_states(engine, snap, period: float | None) -> dict:
    """node -> {alive, alarms, rtt_ms}: the round trip from the scheduled time
    of the tick a node's newest STATUS answers to its arrival (real time only)."""
    out = {}
    for n, s in engine.nodes.nodes.items():
        rtt = None
        if period is not None and snap is not None and s.last_tick is not None and s.received_at:
            sent = snap.time_s - (snap.tick - s.last_tick) * period
            rtt = round((s.received_at - sent) * 1e3, 1)
        out[str(n)] = {"alive": not s.silent and s.statuses > 0,
                       "alarms": [name for bit, name in NODE_ALARMS if s.flags & bit]
                       + (["SILENT"] if s.silent else []),
                       "rtt_ms": rtt}
    return out


def status_line(s: dict) -> str:
    """The headless text line of a status."""
    if s["tick"] is None:
        return STATUS_PREFIX + "waiting for the first tick"
    parts = [f"show {s['show_s']:7.2f}/{s['show_total_s']:.2f} s", f"rate {s['rate']:.3f}"]
    if s["follow_state"] is not None:
        conf = "-" if s["follow_confidence"] is None else f"{s['follow_confidence']:.2f}"
        parts.append(f"follow {s['follow_state']} {conf}")
    if "nodes" in s:
        alive = sum(v["alive"] for v in s["nodes"].values())
        alarms = [f"{n}:{'/'.join(v['alarms'])}" for n, v in s["nodes"].items() if v["alarms"]]
        parts.append(f"nodes {alive}/{len(s['nodes'])} alive" + (f" {' '.join(alarms)}" if alarms else ""))
    parts.append(f"limited {sum(s.get('limited_by_axis', {}).values())}")
    if s["wake_p99_us"] is not None:
        parts.append(f"wake p99 {s['wake_p99_us']:.0f} us")
    parts.append(f"overruns {s['overruns']}")
    r = s["recorder"]
    parts.append(f"rec {r['records']} ({r['dropped']} dropped, ring {r['ring_fill']:.0%})")
    if s["flags"]:
        parts.append("[" + " ".join(s["flags"]) + "]")
    return STATUS_PREFIX + "  ".join(parts)


class View:
    """The headless view, and what the console adds to: Ctrl-C and q end the
    show by a controlled stop (stop_motion, then the end once the figure is
    at rest); a second Ctrl-C (or SIGTERM) e-stops and ends at once."""

    def __init__(self, engine, realtime: bool, json_lines: bool = False, stream=None):
        self.engine = engine
        self.period = engine.config.tick_period
        self.realtime = realtime
        self.json_lines = json_lines
        self.stream = sys.stderr if stream is None else stream
        self.limits = RecordTap(engine.config, self.period)
        if engine.recorder is not None:
            engine.recorder.listeners.append(self.limits)
        self.status = 0                  # the exit status the view asks for
        self.ended_by: str | None = None  # "Ctrl-C", "q", "e-stop", ...
        self.message = ""                # the newest operator action, shown
        self.paused = False
        self._stop_at: float | None = None   # monotonic time a controlled stop began
        self._end = threading.Event()     # the show is to end now
        self._closed = threading.Event()
        self._signals = {}
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._signals[sig] = signal.signal(sig, self._on_signal)
        self._thread = None
        if realtime:
            self._thread = threading.Thread(target=self._loop, name="marionette-view", daemon=True)
            self._thread.start()

    # -- operator actions (any thread) -----------------------------------

    def action(self, key: str) -> None:
        """What a key does (KEYS): an engine request, then the message shown."""
        if key == "q":
            self.controlled_stop("q")
            return
        if key == " ":
            key = "resume" if self.paused else "pause"
        if key in ACTIONS:
            request, paused, message = ACTIONS[key]
            getattr(self.engine, request)()
            self.paused = self.paused if paused is None else paused
            self.message = message

    def controlled_stop(self, why: str) -> None:
        if self._stop_at is None:
            self.engine.stop_motion()
            self._stop_at = time.monotonic()
            self.ended_by = why
            self.message = f"{why}: controlled stop, then the end"

    def _on_signal(self, sig, frame) -> None:
        if sig == signal.SIGINT and self._stop_at is None:
            self.status = 128 + signal.SIGINT     # 130, as a shell reports Ctrl-C
            self.controlled_stop("Ctrl-C")
            return
        self.engine.estop()               # a second Ctrl-C, or SIGTERM
        self.status = 128 + sig                   # 130, or 143 for SIGTERM
        self.ended_by = ("second Ctrl-C" if sig == signal.SIGINT else "SIGTERM") + ": e-stop"
        self._end.set()

    # -- the show's end ---------------------------------------------------

    def _at_rest(self) -> bool:
        if self._stop_at is None:
            return False
        snap = self.engine.snapshot()
        rest = snap is not None and bool(snap.flags & _core.FLAG_HOLDING)
        return rest or time.monotonic() - self._stop_at > STOP_TIMEOUT

    @property
    def ended(self) -> bool:
        if not self._end.is_set() and self._at_rest():
            self._end.set()
        return self._end.is_set()

    def wait(self) -> None:
        """Real time: until the loop stops by itself or the operator ended the show."""
        while not self.ended and not self.engine.wait(timeout=0.01):     # wait: the show's end (--end)
            pass

    def step(self, n: int) -> None:
        """Step mode: n ticks, in chunks, unless the show was ended."""
        while n > 0 and not self.ended:
            k = min(n, STEP_CHUNK)
            self.engine.step(k)
            n -= k

    # -- the view ---------------------------------------------------------

    def _loop(self) -> None:
        while not self._closed.wait(STATUS_INTERVAL):
            self.show(gather(self.engine, self.period, self.realtime, self.limits))

    def show(self, s: dict) -> None:
        line = json.dumps(s) if self.json_lines else status_line(s)
        try:
            print(line, file=self.stream, flush=True)
        except (OSError, ValueError):
            pass

    def close(self) -> None:
        """Stop the view's threads, restore the terminal and the signal
        handlers; say how the show ended. Idempotent."""
        if self._closed.is_set():
            return
        self._closed.set()
        try:
            self._shutdown()
        finally:
            self._restore_signals()

    def _shutdown(self) -> None:
        if self._thread is not None:
            self._thread.join(2.0)

    def _restore_signals(self) -> None:
        for sig, old in self._signals.items():
            signal.signal(sig, old)
        if self.ended_by:
            print(f"play: ended early by {self.ended_by}", file=sys.stderr, flush=True)


def foreground(stream) -> bool:
    """stream is a terminal, and this process is in its foreground job."""
    try:
        fd = stream.fileno()
        return os.isatty(fd) and os.tcgetpgrp(fd) == os.getpgrp()
    except (AttributeError, OSError, ValueError):
        return False


class Keys:
    """Single keys from the terminal in cbreak mode, read on their own thread;
    the terminal's mode is restored by stop() (and at exit, whatever happens)."""

    def __init__(self, on_key, fd: int | None = None):
        import atexit
        import termios
        import tty
        self.fd = sys.stdin.fileno() if fd is None else fd
        self.on_key = on_key
        self._termios = termios
        self._saved = termios.tcgetattr(self.fd)
        tty.setcbreak(self.fd, termios.TCSANOW)
        atexit.register(self.restore)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, name="marionette-keys", daemon=True)
        self._thread.start()

    def _read(self) -> None:
        import select
        while not self._stop.is_set():
            ready, _, _ = select.select([self.fd], [], [], 0.1)
            if not ready:
                continue
            try:
                data = os.read(self.fd, 16)
            except OSError:
                return
            if not data:
                return
            for ch in data.decode(errors="replace").lower():
                self.on_key(ch)

    def restore(self) -> None:
        if self._saved is not None:
            self._termios.tcsetattr(self.fd, self._termios.TCSADRAIN, self._saved)
            self._saved = None

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(1.0)
        self.restore()


class Console(View):
    """The full-screen console (rich), refreshed every REFRESH s on its own thread."""

    def __init__(self, engine, realtime: bool, show_name: str):
        from rich.console import Console as RichConsole
        from rich.live import Live
        self.show_name = show_name
        self.strip: deque = deque(maxlen=STRIP)      # (live, stored) loudness
        self.started = time.monotonic()
        super().__init__(engine, realtime=False)     # no status lines
        self.realtime = realtime
        self.live = Live(console=RichConsole(file=sys.stdout), screen=True, auto_refresh=False,
                         transient=True, redirect_stdout=False, redirect_stderr=False)
        # what others print on stderr meanwhile (the lost-music lines, a lost
        # audio input) is shown in the console and printed again at its end
        self.messages = Messages(sys.stderr)
        sys.stderr = self.messages
        self.live.start()
        # keys only from this job's own terminal: a background job that
        # changed the terminal's mode would be stopped (SIGTTOU)
        self.keys = Keys(self._key) if foreground(sys.stdin) else None
        if self.keys is None:
            self.message = "no keys: stdin is not this job's terminal"
        self._thread = threading.Thread(target=self._loop, name="marionette-console", daemon=True)
        self._thread.start()

    def _key(self, ch: str) -> None:
        try:
            self.action(ch)
        except Exception as exc:          # a refused request is shown, never fatal
            self.message = f"{ch!r}: {exc}"

    def _loop(self) -> None:
        while not self._closed.wait(REFRESH):
            try:
                self.live.update(self.render(gather(self.engine, self.period, self.realtime,
                                                    self.limits)), refresh=True)
            except Exception as exc:      # shown, and the show goes on
                self.message = f"console: {exc}"

    def render(self, s: dict):
        from rich.console import Group
        from rich.panel import Panel
        from rich.table import Table
        from rich.text import Text
        if s["tick"] is not None:
            self.strip.append(self.limits.loudness)
        mode = "real time" if self.realtime else "step mode"
        top = Table.grid(padding=(0, 2))
        if s["tick"] is None:
            top.add_row("waiting for the first tick")
        else:
            top.add_row(f"show {s['show_s']:7.2f} / {s['show_total_s']:.2f} s",
                        f"position {s['position']:9.1f} ticks", f"rate {s['rate']:.3f}",
                        f"tick {s['tick']}", " ".join(s["flags"]).upper() or "playing")
        state = "PAUSED" if self.paused else "running"
        header = Panel(top, title=f"marionette play {self.show_name} ({mode}) - {state}",
                       title_align="left")
        if s["tick"] is not None and s["follow_state"] is not None:
            conf = "-" if s["follow_confidence"] is None else f"{s['follow_confidence']:.2f}"
            state_line = f"follower {s['follow_state']}, confidence {conf}"
        else:
            state_line = "no follower: the rate drives the show"
        strips = Table.grid(padding=(0, 1))
        live, stored = zip(*self.strip) if self.strip else ((), ())
        strips.add_row("live  ", Text(sparkline(live, stored), style="cyan", no_wrap=True))
        strips.add_row("stored", Text(sparkline(stored, live), style="magenta", no_wrap=True))
        follow = Group(Text(state_line), strips)
        limits = Table("axis", f"limited (last {LIMIT_WINDOW:g} s)", "in all", box=None,
                       pad_edge=False)
        busy = [(n, r, t) for n, (r, t) in self.limits.by_axis().items() if r or t]
        for n, r, t in sorted(busy, key=lambda x: (-x[1], -x[2]))[:8]:
            limits.add_row(n, str(r), str(t), style="bold red" if r else None)
        if not busy:
            limits.add_row("(none)", "0", "0")
        timing = Table.grid(padding=(0, 2))
        wake = "-" if s["wake_p99_us"] is None else f"{s['wake_p99_us']:.1f} us"
        timing.add_row(f"wake latency p99 {wake}", f"overruns {s['overruns']}")
        r = s["recorder"]
        timing.add_row(f"flight recorder {r['records']} records, {r['dropped']} dropped",
                       f"ring {r['ring_fill']:.0%} full")
        parts = [header, Panel(follow, title="music"), Panel(limits, title="limiter by axis"),
                 Panel(timing, title="timing and recorder")]
        if "nodes" in s:
            nodes = Table("node", "state", "alarms", "round trip", box=None, pad_edge=False)
            for n, v in s["nodes"].items():
                nodes.add_row(n, "alive" if v["alive"] else "SILENT", " ".join(v["alarms"]) or "-",
                              "-" if v["rtt_ms"] is None else f"{v['rtt_ms']:.1f} ms",
                              style=None if v["alive"] and not v["alarms"] else "bold red")
            parts.append(Panel(nodes, title="servo nodes"))
        keys = "   ".join(f"[bold]{k}[/bold] {what}" for k, what in KEYS)
        parts.append(Panel(Text.from_markup(keys + (f"\n{self.message}" if self.message else "")),
                           title="keys"))
        if self.messages.lines:
            parts.append(Panel(Text("\n".join(list(self.messages.lines)[-MESSAGES:])),
                               title="messages"))
        return Group(*parts)

    def _shutdown(self) -> None:
        try:
            self._thread.join(2.0)
            if self.keys is not None:
                self.keys.stop()
        finally:
            self.live.stop()
            sys.stderr = self.messages.stream
            for line in self.messages.lines + ([self.messages._part] if self.messages._part else []):
                print(line, file=sys.stderr, flush=True)


class Messages:
    """A stand-in for sys.stderr while the console is up: keeps whole lines."""

    def __init__(self, stream):
        self.stream = stream
        self.lines: list[str] = []
        self._part = ""
        self._lock = threading.Lock()

    def write(self, text: str) -> int:
        with self._lock:
            *whole, self._part = (self._part + text).split("\n")
            self.lines.extend(whole)
        return len(text)

    def flush(self) -> None:
        pass

    def isatty(self) -> bool:
        return False

    def fileno(self) -> int:
        return self.stream.fileno()


def sparkline(values, other) -> str:
    """values as bars on a scale shared with other (NaN: a blank)."""
    both = [v for v in (*values, *other) if v is not None and np.isfinite(v)]
    top = max(both) if both else 1.0
    top = top if top > 0 else 1.0
    out = []
    for v in values:
        if v is None or not np.isfinite(v):
            out.append(" ")
        else:
            out.append(BARS[min(len(BARS) - 1, int(round(v / top * (len(BARS) - 1))))])
    return "".join(out).rjust(STRIP)


def open_view(args, engine) -> View:
    """The console on a terminal (unless --headless, --json or rich is
    missing), else the headless view: status lines on stderr in real time."""
    realtime = bool(args.realtime)
    json_lines = bool(getattr(args, "json", False))
    if not (getattr(args, "headless", False) or json_lines) and sys.stdout.isatty():
        try:
            import rich  # noqa: F401
        except ImportError:
            print("play: no live console without the 'console' extra (pip install "
                  "'marionette[console]'); headless", file=sys.stderr, flush=True)
        else:
            return Console(engine, realtime, os.path.basename(str(engine.show.path)))
    return View(engine, realtime, json_lines)
