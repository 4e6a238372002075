"""Watches the servo nodes while the engine runs: starts the link's receive
path, finds silent nodes once per tick, and marks silent or faulted nodes
in every flight record (the record's node_alarms bits).

Also the operator's messages to the nodes that are not setpoints: CONFIG
(limits, watchdog), ESTOP and its release.
"""
from __future__ import annotations

import threading

from marionette import protocol
from marionette.config import FigureConfig
from marionette.transport.node_monitor import NodeMonitor

POLL = 0.004                # how often the supervisor looks at the tick counter [s]


class LinkSupervisor:
    def __init__(self, link, config: FigureConfig, current_tick, set_alarms,
                 poll_one: bool = False, on_loudness=None, log_path=None):
        """current_tick(): the engine's latest tick number (or None before the first);
        set_alarms(alarms, silent): hands the alarm bits, and those of the
        silent nodes, to the C tick, which applies the figure's [faults]
        silent_node at its next tick; poll_one: each
        SYNC polls one node in turn; log_path: where every STATUS is written
        (beside the flight record), or None."""
        self.link = link
        self.config = config
        self._log = open(log_path, "w") if log_path is not None else None
        nodes = {a.node for a in config.axes}
        self.nodes = NodeMonitor(nodes, on_loudness=on_loudness, log=self._log,
                                 poll_interval=len(nodes) if poll_one else 1)
        # (engine tick, node, evidence tick) of each silent-node report
        self.reports: list[tuple[int, int, int]] = []
        self.estop_sent = False             # the [faults] silent_node = "estop" reaction was sent
        self._current_tick = current_tick
        self._set_alarms = set_alarms
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        link.start_receiving(self.nodes)

    def start(self) -> None:
        """Check the nodes once per tick while the real-time loop runs."""
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._watch, name="marionette-nodes", daemon=True)
            self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(1.0)
            self._thread = None
        if self._log is not None:
            self._log.flush()

    def close(self) -> None:
        """Stop, and close the status log (the link stays open: it is the caller's)."""
        self.stop()
        if self._log is not None:
            with self.nodes._lock:
                self._log.close()
                self.nodes.log = None
            self._log = None

    def check(self) -> None:
        tick = self._current_tick()
        if tick is None:
            return
        found = self.nodes.check(tick)
        self._set_alarms(self.nodes.alarm_mask(), self.nodes.silent_mask())
        for node, evidence in found:
            self.reports.append((tick, node, evidence))
        if found and self.config.faults.silent_node == "estop" and not self.estop_sent:
            self.estop_sent = True          # the tick's stop ramp is on its way already
            try:
                self.estop()
            except (OSError, ValueError):   # the link itself is gone (serial.SerialException is an OSError)
                pass

    def _watch(self) -> None:
        last = None
        while not self._stop.wait(POLL):
            tick = self._current_tick()
            if tick != last:
                last = tick
                self.check()

    # -- messages to the nodes ---------------------------------------------

    def configure(self, watchdog_ticks: int = 5) -> None:
        """Send every node its limits (in counts) and the watchdog time."""
        for node in sorted(self.nodes.nodes):
            self.link.send(protocol.node_config(self.config, node, watchdog_ticks))

    def estop(self, node: int = protocol.BROADCAST) -> None:
        self.link.send(protocol.Estop(node))

    def release(self, node: int = protocol.BROADCAST) -> None:
        self.link.send(protocol.EstopRelease(node))
