"""What the control PC knows about each servo node: its last status, how old
that is, and what went wrong on the way back.

The transports' receive threads hand it every message that comes back
(take); the engine's monitor thread calls check() once per tick to find
nodes that fell silent. Thread-safe through one lock; nothing here runs in
the C tick.
"""
from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field

from marionette import protocol

HISTORY = 15000             # statuses kept per node: 5 min at 50 Hz
SILENT_AFTER_TICKS = 3      # a node that missed this many STATUS answers in a row is silent [ticks]
LINK_LOST_TICKS = 25        # no STATUS from any node for this long: every node is silent [ticks]


@dataclass
class NodeState:
    node: int
    last_tick: int | None = None            # tick counter of the newest status
    received_at: float | None = None        # monotonic time of the newest status [s]
    flags: int = 0                          # status flags of the newest status
    positions: tuple[int, ...] = ()         # actual positions [counts] per channel
    rejected: int = 0                       # frames the node refused (its newest STATUS, mod 2^16)
    seq_gaps: int = 0                       # ticks it got no setpoint for (ditto)
    statuses: int = 0                       # statuses received
    heartbeats: int = 0
    errors: int = 0                         # ERROR/NACK and EMCY messages received
    silent: bool = False                    # reported silent and not heard from since
    silent_events: int = 0
    # (time [s], tick, flags, positions) of the newest statuses
    history: deque = field(default_factory=lambda: deque(maxlen=HISTORY), repr=False)


class NodeMonitor:
    """Per-node state for the nodes a figure uses."""

    def __init__(self, nodes: Iterable[int], keep_history: bool = True, on_loudness=None,
                 log=None, poll_interval: int = 1):
        """log: a text file that gets one line per STATUS (docs/formats.md);
        poll_interval: ticks between two SYNCs that poll a node [ticks]."""
        self.nodes = {n: NodeState(n) for n in sorted(set(nodes))}
        self.poll_interval = poll_interval
        self.log = log
        if log is not None:
            log.write("time_s,node,tick,flags,state,rejected,seq_gaps,positions\n")
        self.on_loudness = on_loudness      # called with each LOUDNESS's value and bands (None: one band)
        self.keep_history = keep_history
        self.frames_ok = 0
        self.frames_bad = 0                                     # rejected by the deframer or decoder
        self.unknown_nodes = 0                                  # messages from nodes not in the figure
        self.events: list[tuple[float, str]] = []               # (monotonic time [s], text)
        self._lock = threading.Lock()

    def _state(self, node: int) -> NodeState | None:
        s = self.nodes.get(node)
        if s is None:
            self.unknown_nodes += 1
        return s

    def take(self, message, now: float | None = None) -> None:
        """One message from the nodes."""
        if isinstance(message, protocol.Status):
            now = time.monotonic() if now is None else now
            self.on_status(message.node, message.tick, message.flags, message.positions, now,
                           message.rejected, message.seq_gaps)
            with self._lock:
                if self.log is not None:
                    self.log.write(f"{now:.6f},{message.node},{message.tick},{message.flags},"
                                   f"{message.state},{message.rejected},{message.seq_gaps},"
                                   f"{';'.join(map(str, message.positions))}\n")
        elif isinstance(message, protocol.Heartbeat):
            self.on_heartbeat(message.node, now)
        elif isinstance(message, protocol.Nack):
            if message.reason == protocol.REASON_ACCEPTED:
                self.on_heartbeat(message.node, now)
            else:
                self.on_error(message.node, message.describe(), now)
        elif isinstance(message, protocol.Loudness):
            with self._lock:
                self.frames_ok += 1
            if self.on_loudness is not None:
                self.on_loudness(message.value, message.bands)

    def on_status(self, node: int, tick: int, flags: int, positions, now: float | None = None,
                  rejected: int = 0, seq_gaps: int = 0) -> None:
        now = time.monotonic() if now is None else now
        with self._lock:
            self.frames_ok += 1
            s = self._state(node)
            if s is None:
                return
            if s.silent:
                s.silent = False
                self.events.append((now, f"node {node} answers again"))
            s.last_tick, s.received_at, s.flags = tick, now, flags
            s.rejected, s.seq_gaps = rejected, seq_gaps
            s.positions = tuple(int(p) for p in positions)
            s.statuses += 1
            if self.keep_history:
                s.history.append((now, tick, flags, s.positions))

    def on_heartbeat(self, node: int, now: float | None = None) -> None:
        with self._lock:
            self.frames_ok += 1
            s = self._state(node)
            if s is not None:
                s.heartbeats += 1

    def on_error(self, node: int, text: str, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        with self._lock:
            self.frames_ok += 1
            s = self._state(node)
            if s is not None:
                s.errors += 1
            self.events.append((now, f"node {node}: {text}"))

    def on_bad_frame(self, count: int = 1) -> None:
        with self._lock:
            self.frames_bad += count

    def check(self, tick: int, now: float | None = None) -> list[tuple[int, int]]:
        """(node, evidence tick) of nodes newly found silent at engine tick `tick`.

        A node is silent when it missed SILENT_AFTER_TICKS polls that the
        other nodes' answers show were sent (with one node polled per tick,
        every poll_interval-th SYNC polls a given node): so a receive path
        that lags under load does not make every node look silent. The
        evidence tick is the poll that gave it away, the SILENT_AFTER_TICKS-th
        missed one, however late the answers proving it came. When no node
        answers for LINK_LOST_TICKS, all are silent (evidence: the newest
        tick anyone answered)."""
        now = time.monotonic() if now is None else now
        found = []
        with self._lock:
            answered = [s.last_tick for s in self.nodes.values() if s.last_tick is not None]
            reference = max(answered, default=-1)
            link_lost = tick - reference > LINK_LOST_TICKS
            for s in self.nodes.values():
                if s.silent:
                    continue
                newest = -1 if s.last_tick is None else s.last_tick
                if (reference - newest) // self.poll_interval >= SILENT_AFTER_TICKS or link_lost:
                    s.silent = True
                    s.silent_events += 1
                    evidence = (max(reference, newest) if link_lost
                                else newest + SILENT_AFTER_TICKS * self.poll_interval)
                    found.append((s.node, evidence))
                    self.events.append((now, f"node {s.node} silent: no STATUS after tick {newest}"))
        return found

    def alarm_mask(self) -> int:
        """Bit i set when the i-th node (ascending) is silent or reports a fault or e-stop."""
        mask = 0
        with self._lock:
            for i, s in enumerate(self.nodes.values()):
                if s.silent or s.flags & (protocol.FLAG_FAULT | protocol.FLAG_ESTOP):
                    mask |= 1 << i
        return mask

    def silent_mask(self) -> int:
        """Bit i set when the i-th node (ascending) is silent."""
        with self._lock:
            return sum(1 << i for i, s in enumerate(self.nodes.values()) if s.silent)

    def summary(self) -> dict:
        with self._lock:
            return {"frames_ok": self.frames_ok, "frames_bad": self.frames_bad,
                    "unknown_nodes": self.unknown_nodes,
                    "nodes": {n: {"last_tick": s.last_tick, "flags": s.flags, "statuses": s.statuses,
                                  "heartbeats": s.heartbeats, "errors": s.errors, "silent": s.silent,
                                  "silent_events": s.silent_events, "positions": list(s.positions)}
                              for n, s in self.nodes.items()}}
