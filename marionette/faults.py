"""What `play` tells the operator about the fault reactions of the figure's
[faults] table (docs/formats.md): a line on stderr as each one happens
(FaultWatcher, a thread polling snapshots, never touching the tick), and
the summary's lines and exit status from the flight record.

The reactions themselves run in the C tick (ext/mar_engine.c,
react_to_faults): the supervisor hands it the silent nodes, the real-time
loop the overruns.
"""
from __future__ import annotations

import sys
import threading

import numpy as np

from marionette import _core

REACTIONS = {"stop": "every axis to rest at its limits, held (latched)",
             "hold": "every axis to rest at its limits, held until every node answers again",
             "estop": "ESTOP to the nodes, every axis to rest at its limits (latched)",
             "continue": "the show plays on"}
REST_TOLERANCE = 1e-9       # a command that moves less than this per tick is at rest [unit]


def silent_names(engine) -> str:
    nodes = engine.nodes
    if nodes is None:
        return "a node"
    silent = [f"{n} (no STATUS after tick {s['last_tick']})"
              for n, s in nodes.summary()["nodes"].items() if s["silent"]]
    return ("node " + ", ".join(silent)) if silent else "a node"


class FaultWatcher:
    """Tells on stderr, within a poll, when a node falls silent, what the
    tick does about it, when it answers again, and an overrun stop."""

    def __init__(self, engine, period: float, out=None):
        self.engine = engine
        self.reaction = engine.config.faults.silent_node
        self.period = period
        self.out = out if out is not None else sys.stderr
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> FaultWatcher:
        """Watches only where a fault can come: a link to nodes, or an overrun threshold."""
        if self.engine.supervisor is None and not self.engine.config.faults.overruns:
            return self
        self._thread = threading.Thread(target=self._run, name="marionette-faults", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(1.0)
            self._thread = None

    def _say(self, text: str) -> None:
        print(f"marionette: {text}", file=self.out, flush=True)

    def _run(self) -> None:
        before = 0
        while not self._stop.wait(self.period / 2):
            rec = self.engine._core.snapshot()      # the raw record: cheap, polled every half tick
            if rec is None:
                continue
            flags, tick = int(rec["flags"]), int(rec["tick"])
            new, gone = flags & ~before, before & ~flags
            before = flags
            at = f"tick {tick} ({tick * self.period:.2f} s)"
            if new & _core.FLAG_NODE_SILENT:
                who = ("the link to the servo nodes is gone (its writes fail for good) "
                       f"at {at}: every node silent" if new & _core.FLAG_LINK_LOST
                       else f"{silent_names(self.engine)} silent at {at}")
                self._say(f"{who}: silent_node = {self.reaction}: {REACTIONS[self.reaction]}")
            if new & _core.FLAG_OVERRUNS:
                self._say(f"{self.engine.stats()['overruns']} real-time overruns at {at} (threshold "
                          f"{self.engine.config.faults.overruns}): every axis to rest at its "
                          f"limits, held (latched)")
            if gone & _core.FLAG_NODE_SILENT:
                self._say(f"every node answers again at {at}"
                          + (": blending back into the show" if gone & _core.FLAG_FAULT_HOLD else ""))


def rest_after(records: np.ndarray, config, start: int) -> tuple[int | None, float]:
    """From record index start: (records until every command is at rest for
    good, None if it never is; the time the limits allow [s]: the slowest
    axis's speed before start over its top acceleration). The stop ramp
    brakes each drive from its own speed, which its lag makes an average
    of its commands' past speeds: the higher of the two counts. The ramp's
    commands lead the drive by a tick and take one more to step back to
    rest, so they rest two ticks after it."""
    cmd = records["command"]
    period = config.tick_period
    start = max(start, 2)
    step = np.abs(np.diff(cmd[start - 1:], axis=0)).max(axis=1)   # [unit/tick] into records start..
    moving = np.nonzero(step > REST_TOLERANCE)[0]
    rest = 0 if len(moving) == 0 else int(moving[-1]) + 1
    rest = None if rest >= len(step) else rest
    tau = np.array([a.time_constant for a in config.axes])             # [s]
    alpha = -np.expm1(-period / np.maximum(tau, 1e-300))               # share of the gap a tick closes
    memory = int(np.ceil(10 * tau.max() / period)) + 2                 # [ticks] the lag remembers
    drive = np.zeros(len(tau))                                         # [unit/s]
    for v in np.diff(cmd[max(0, start - memory):start], axis=0) / period:
        drive += alpha * (v - drive)
    speed = np.maximum(np.abs(cmd[start - 1] - cmd[start - 2]) / period, np.abs(drive))   # [unit/s]
    allowed = max(s / a.max_accel for s, a in zip(speed, config.axes))
    return rest, float(allowed)


def summary(records: np.ndarray, config, overruns: int) -> tuple[list[str], int]:
    """The summary's fault lines and the exit status: 1 when the show ended
    on a fault (a fault stopped it, or it ended held for, or with, a silent node)."""
    if len(records) == 0:
        return [], 0
    flags = records["flags"]
    period = config.tick_period
    faults = config.faults
    lines = []
    silent = np.nonzero(flags & _core.FLAG_NODE_SILENT)[0]
    stopped = np.nonzero(flags & (_core.FLAG_FAULT_STOP | _core.FLAG_FAULT_HOLD))[0]
    if len(silent):
        k = int(silent[0])
        lost = np.nonzero(flags & _core.FLAG_LINK_LOST)[0]
        if len(lost):
            lines.append(f"  faults: the link to the servo nodes gone at tick {int(records['tick'][lost[0]])} "
                         f"({lost[0] * period:.2f} s; its writes fail for good)")
        lines.append(f"  faults: a node silent from tick {int(records['tick'][k])} "
                     f"({k * period:.2f} s), {len(silent)} ticks in all; silent_node = "
                     f"{faults.silent_node}: {REACTIONS[faults.silent_node]}")
    if np.any(flags & _core.FLAG_OVERRUNS):
        k = int(np.nonzero(flags & _core.FLAG_OVERRUNS)[0][0])
        lines.append(f"  faults: {faults.overruns} real-time overruns reached at tick "
                     f"{int(records['tick'][k])}: the show stopped there")
    if len(stopped):
        k = int(stopped[0])
        rest, allowed = rest_after(records, config, k)
        lines.append(f"  fault reaction from tick {int(records['tick'][k])}: "
                     + (f"every axis at rest {rest * period:.2f} s later (its limits allow "
                        f"{allowed:.2f} s)" if rest is not None else "not at rest by the end"))
    elif faults.overruns:
        lines.append(f"  overruns {overruns} (threshold {faults.overruns})")
    ended_on_fault = bool(np.any(flags & _core.FLAG_FAULT_STOP)
                          or flags[-1] & (_core.FLAG_FAULT_HOLD | _core.FLAG_NODE_SILENT))
    if ended_on_fault:
        lines.append("  the show ended on a fault")
    return lines, 1 if ended_on_fault else 0
