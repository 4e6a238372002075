"""One simulated servo node: the node semantics of firmware_protocol/SPEC.md
on top of the servo behaviour model.

Independent of the wire: the simulator's serial and CAN front ends decode
frames and call the on_* methods; status() makes the node's answer.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from marionette.config import AxisConfig
from marionette.sim.servo import ServoModel

# status flags (firmware_protocol/SPEC.md)
FLAG_LIMIT = 0x01           # a setpoint was clamped to the channel's limits
FLAG_FAULT = 0x02           # the drive reports a fault
FLAG_WATCHDOG = 0x04        # no setpoint within the watchdog time: stopping or stopped
FLAG_FOLLOWING = 0x08       # following error above the threshold
FLAG_ESTOP = 0x10           # e-stop latched

DEFAULT_WATCHDOG_TICKS = 5          # [ticks] without a setpoint before the node stops
FOLLOWING_ERROR = 0.25              # threshold, as a fraction of the channel's range


@dataclass
class NodeCounters:
    setpoints: int = 0          # setpoint messages taken
    seq_gaps: int = 0           # tick counters skipped between setpoint messages
    clamped: int = 0            # setpoints clamped to the limits
    ignored_estop: int = 0      # setpoints ignored while the e-stop is latched
    watchdog_trips: int = 0


class SimNode:
    """A node with channels 0..k-1 (the figure's axes on this node)."""

    def __init__(self, node: int, axes: Sequence[AxisConfig], tick_period: float,
                 watchdog_ticks: int = DEFAULT_WATCHDOG_TICKS):
        self.node = node
        self.axes = sorted(axes, key=lambda a: a.channel)
        self.channels = [a.channel for a in self.axes]
        self.tick_period = tick_period                                      # [s]
        self.model = ServoModel(self.axes, tick_period)
        self.scale = np.array([a.scale for a in self.axes])                 # [counts/unit]
        self.offset = np.array([a.offset for a in self.axes])               # [counts]
        self.min_counts = np.array([self.counts_of(j, a.min) for j, a in enumerate(self.axes)])
        self.max_counts = np.array([self.counts_of(j, a.max) for j, a in enumerate(self.axes)])
        self.watchdog_ticks = watchdog_ticks
        self.counters = NodeCounters()
        self.last_tick: int | None = None       # tick counter of the last setpoint
        self.last_setpoint_time = 0.0           # model time of the last setpoint [s]
        self.estop = False
        self.watchdog = False
        self.limited = False

    def counts_of(self, j: int, position: float) -> float:
        """Device counts of a position [unit] on channel j."""
        return float(np.rint(self.offset[j] + self.scale[j] * position))

    def advance_to(self, t: float) -> None:
        """Run the drives up to model time t [s]; the watchdog acts on the way."""
        deadline = self.last_setpoint_time + self.watchdog_ticks * self.tick_period
        if not self.watchdog and not self.estop and t > deadline:
            self.model.advance_to(deadline)
            self.watchdog = True
            self.counters.watchdog_trips += 1
            self._ramp_to_rest()
        self.model.advance_to(t)

    def _ramp_to_rest(self) -> None:
        """Command the point where each channel can stop at its acceleration limit."""
        v = self.model.velocity
        stop = self.model.position + v * np.abs(v) / (2 * self.model.max_accel)
        self.model.set_command(np.clip(stop, self.model.lower, self.model.upper))

    def on_setpoint(self, tick: int, channel: int, counts: int, t: float) -> None:
        """A setpoint [counts] for one channel, tick counter `tick`, at model time t [s]."""
        self.advance_to(t)
        if channel not in self.channels:
            return
        if self.estop:
            self.counters.ignored_estop += 1
            return
        j = self.channels.index(channel)
        lo, hi = sorted((self.min_counts[j], self.max_counts[j]))
        clamped = min(max(counts, lo), hi)
        if clamped != counts:
            self.counters.clamped += 1
            self.limited = True
        self.model.set_channel(j, (clamped - self.offset[j]) / self.scale[j])
        self.counters.setpoints += 1
        self.last_setpoint_time = t
        self.watchdog = False

    def on_tick(self, tick: int) -> None:
        """A setpoint batch for this tick counter arrived; counts gaps (mod 2^32)."""
        if self.last_tick is not None:
            gap = (tick - self.last_tick - 1) % (1 << 32)
            if gap < (1 << 31):
                self.counters.seq_gaps += gap
        self.last_tick = tick

    def on_estop(self, t: float) -> None:
        self.advance_to(t)
        if not self.estop:
            self.estop = True
            self._ramp_to_rest()

    def on_release(self, t: float) -> None:
        """Release the e-stop latch; the node holds where it stopped until new setpoints come."""
        self.advance_to(t)
        self.estop = False
        self.last_setpoint_time = t

    def flags(self) -> int:
        f = 0
        if self.limited:
            f |= FLAG_LIMIT
        if self.watchdog:
            f |= FLAG_WATCHDOG
        if self.estop:
            f |= FLAG_ESTOP
        span = np.abs(self.model.upper - self.model.lower)
        if np.any(np.abs(self.model.command - self.model.position) > FOLLOWING_ERROR * span):
            f |= FLAG_FOLLOWING
        return f

    def actual_counts(self, noise: np.ndarray | None = None) -> np.ndarray:
        """Actual positions [counts] per channel, as the encoders report them."""
        x = self.offset + self.scale * self.model.position
        if noise is not None:
            x = x + noise
        return np.rint(x).astype(np.int64)
