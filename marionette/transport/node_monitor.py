"""What the control PC knows about each servo node: its last status, how old
that is, and what went wrong on the way back.

The transports' receive threads call on_status/on_heartbeat/on_error; the
engine's drain thread calls check() once per tick to find nodes that fell
silent. Thread-safe through one lock; nothing here runs in the C tick.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass, field

SILENT_AFTER_TICKS = 3      # a node is reported silent when its newest status is this old [ticks]


@dataclass
class NodeState:
    node: int
    last_tick: int | None = None            # tick counter of the newest status
    received_at: float | None = None        # monotonic time of the newest status [s]
    flags: int = 0                          # status flags of the newest status
    positions: tuple[int, ...] = ()         # actual positions [counts] per channel
    statuses: int = 0                       # statuses received
    heartbeats: int = 0
    errors: int = 0                         # ERROR/NACK and EMCY messages received
    silent: bool = False                    # reported silent and not heard from since
    silent_events: int = 0
    history: list = field(default_factory=list, repr=False)   # (time [s], tick, flags) of each status


class NodeMonitor:
    """Per-node state for the nodes a figure uses."""

    def __init__(self, nodes: Iterable[int], tick_period: float, keep_history: bool = True):
        self.tick_period = tick_period                          # [s]
        self.nodes = {n: NodeState(n) for n in sorted(set(nodes))}
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

    def on_status(self, node: int, tick: int, flags: int, positions, now: float | None = None) -> None:
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
            s.positions = tuple(int(p) for p in positions)
            s.statuses += 1
            if self.keep_history:
                s.history.append((now, tick, flags))

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

    def check(self, now: float | None = None) -> list[int]:
        """Nodes newly found silent (no status for SILENT_AFTER_TICKS ticks)."""
        now = time.monotonic() if now is None else now
        limit = SILENT_AFTER_TICKS * self.tick_period
        found = []
        with self._lock:
            for s in self.nodes.values():
                if s.silent or s.received_at is None:
                    continue
                if now - s.received_at > limit:
                    s.silent = True
                    s.silent_events += 1
                    found.append(s.node)
                    self.events.append((now, f"node {s.node} silent for more than "
                                             f"{SILENT_AFTER_TICKS} ticks"))
        return found

    def alarm_mask(self) -> int:
        """Bit i set when the i-th node (ascending) is silent or reports a fault or e-stop."""
        mask = 0
        with self._lock:
            for i, s in enumerate(self.nodes.values()):
                if s.silent or s.flags & 0x12:          # FAULT | ESTOP
                    mask |= 1 << i
        return mask

    def summary(self) -> dict:
        with self._lock:
            return {"frames_ok": self.frames_ok, "frames_bad": self.frames_bad,
                    "unknown_nodes": self.unknown_nodes,
                    "nodes": {n: {"last_tick": s.last_tick, "flags": s.flags, "statuses": s.statuses,
                                  "heartbeats": s.heartbeats, "errors": s.errors, "silent": s.silent,
                                  "silent_events": s.silent_events, "positions": list(s.positions)}
                              for n, s in self.nodes.items()}}
