"""One simulated servo node: the node semantics of firmware_protocol/SPEC.md
on top of the servo behaviour model.

Independent of the wire: the simulator's serial and CAN front ends decode
frames and call the on_* methods; status() makes the node's answer.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from marionette import protocol
from marionette.config import AxisConfig
from marionette.sim.servo import ServoModel

HEARTBEAT_TICKS = 50                # a HEARTBEAT at least this often, and at each state change [ticks]
DEFAULT_WATCHDOG_TICKS = 5          # [ticks] without a setpoint before the node brakes (SPEC.md)
FOLLOWING_ERROR = 0.25              # threshold, as a fraction of the channel's range


@dataclass
class NodeCounters:
    setpoints: int = 0          # setpoints taken [channel-ticks]
    seq_gaps: int = 0           # tick counters skipped between setpoint messages
    clamped: int = 0            # setpoints clamped to the limits
    stale: int = 0              # setpoint frames older than the last accepted one
    refused: int = 0            # frames for this node (or every node) whose content was refused
    ignored_estop: int = 0      # setpoints ignored while the e-stop is latched
    watchdog_trips: int = 0


class SimNode:
    """A node with channels 0..k-1 (the figure's axes on this node)."""

    def __init__(self, node: int, axes: Sequence[AxisConfig], tick_period: float,
                 watchdog_ticks: int = DEFAULT_WATCHDOG_TICKS, clip_accel: bool = True):
        self.node = node
        self.axes = sorted(axes, key=lambda a: a.channel)
        self.channels = [a.channel for a in self.axes]
        self.tick_period = tick_period                                      # [s]
        self.model = ServoModel(self.axes, tick_period, clip_accel=clip_accel)
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
        self.limited = False                    # clamped a setpoint since the last STATUS
        self.following = False                  # has had a setpoint since start or the last stop
        self.nacked_estop = False               # told the host its setpoints are ignored
        self.pending_nack: protocol.Nack | None = None   # sent after the next STATUS
        self.last_sync: int | None = None
        self.heartbeat_state: int | None = None # state in the last HEARTBEAT (None: BOOT not sent)
        self.heartbeat_due = 0                  # SYNCs until the next HEARTBEAT
        self.heartbeats = 0                     # HEARTBEATs sent: the next one's seq

    def counts_of(self, j: int, position: float) -> float:
        """Device counts of a position [unit] on channel j."""
        return float(np.rint(self.offset[j] + self.scale[j] * position))

    def advance_to(self, t: float) -> None:
        """Run the drives up to model time t [s]; the watchdog acts on the way."""
        deadline = self.last_setpoint_time + self.watchdog_ticks * self.tick_period
        if self.following and not self.watchdog and not self.estop and t > deadline:
            self.model.advance_to(deadline)
            self.watchdog = True
            self.counters.watchdog_trips += 1
            self._ramp_to_rest()
        self.model.advance_to(t)

    def _ramp_to_rest(self) -> None:
        """The quick stop (SPEC.md 6): every channel's drive brakes at its
        acceleration limit from its own motion to its stop point, whatever
        setpoints are still inside its dead time (ServoModel.brake)."""
        self.model.brake()

    def on_setpoint(self, tick: int, channel: int, counts: int, t: float) -> None:
        """A setpoint [counts] for one channel, tick counter `tick`, at model time t [s]
        (after on_tick accepted the frame's tick)."""
        self.advance_to(t)
        if channel not in self.channels:
            self._nack(protocol.REASON_BAD_CHANNEL, protocol.SETPOINT, tick)
            return
        if self.estop:
            self.counters.ignored_estop += 1
            if not self.nacked_estop:
                self.nacked_estop = True
                self._nack(protocol.REASON_ESTOP_LATCHED, protocol.SETPOINT, tick)
            return
        j = self.channels.index(channel)
        lo, hi = sorted((self.min_counts[j], self.max_counts[j]))
        clamped = min(max(counts, lo), hi)
        if clamped != counts:
            self.counters.clamped += 1
            self.limited = True
        if self.watchdog:                       # following again after the watchdog's stop
            self.model.release()
        self.model.set_channel(j, (clamped - self.offset[j]) / self.scale[j])
        self.counters.setpoints += 1
        self.last_setpoint_time = t
        self.watchdog = False
        self.following = True

    def _nack_now(self, reason: int, ref_type: int, ref_seq: int) -> protocol.Nack:
        """A NACK; its seq is the tick of the last SYNC (SPEC.md 6, HEARTBEAT)."""
        return protocol.Nack(self.node, reason, ref_type, ref_seq, self.flags(), self.last_sync or 0)

    def _nack(self, reason: int, ref_type: int, ref_seq: int) -> None:
        if self.pending_nack is None:           # one per answer; more are only counted
            self.pending_nack = self._nack_now(reason, ref_type, ref_seq)

    def on_refused(self, refused: protocol.Refused, alone: bool) -> list:
        """A frame for this node (alone) or every node whose content was
        refused: counted; answered when addressed to this node alone, a
        CONFIG's at once, the others after the next STATUS."""
        self.counters.refused += 1
        if not alone:
            return []
        if refused.type == protocol.CONFIG:
            return [self._nack_now(refused.reason, refused.type, refused.seq)]
        self._nack(refused.reason, refused.type, refused.seq)
        return []

    def on_tick(self, tick: int) -> bool:
        """A setpoint frame for tick counter `tick` arrived: False when it is
        stale (older than the last accepted); counts skipped ticks (mod 2^32)."""
        if self.last_tick is not None:
            d = (tick - self.last_tick) % (1 << 32)
            if d >= 1 << 31:
                self.counters.stale += 1
                return False
            if d > 1:
                self.counters.seq_gaps += d - 1
        self.last_tick = tick
        return True

    def on_sync(self, tick: int) -> None:
        """A SYNC not newer than the last one means the host restarted."""
        if self.last_sync is not None:
            d = (tick - self.last_sync) % (1 << 32)
            if d == 0 or d >= 1 << 31:
                self.last_tick = None
        self.last_sync = tick

    def on_estop(self, t: float) -> None:
        self.advance_to(t)
        if not self.estop:
            self.estop = True
            self.nacked_estop = False
            self._ramp_to_rest()

    def on_release(self, t: float) -> None:
        """Release the e-stop latch; the node holds where it stopped until new setpoints come."""
        self.advance_to(t)
        if self.estop:
            self.estop = False
            self.following = False              # PRE_OPERATIONAL until the next setpoint
            self.last_tick = None
            self.model.release()                            # hold where it stopped

    def on_config(self, config: protocol.Config, t: float) -> list:
        """Take new limits and watchdog time; answers with a NACK (reason 0: accepted)."""
        self.advance_to(t)
        reason = protocol.config_reason(config)
        if reason == protocol.REASON_ACCEPTED and any(c.channel not in self.channels
                                                     for c in config.channels):
            reason = protocol.REASON_BAD_CHANNEL
        if reason == protocol.REASON_ACCEPTED:
            self.watchdog_ticks = config.watchdog_ticks
            self.tick_period = config.tick_period_us * 1e-6
            for c in config.channels:
                j = self.channels.index(c.channel)
                self.min_counts[j], self.max_counts[j] = c.min_counts, c.max_counts
        return [self._nack_now(reason, protocol.CONFIG, config.seq)]

    def flags(self) -> int:
        f = 0
        if self.limited:
            f |= protocol.FLAG_LIMIT
        if self.watchdog:
            f |= protocol.FLAG_WATCHDOG
        if self.estop:
            f |= protocol.FLAG_ESTOP
        span = np.abs(self.model.upper - self.model.lower)
        if np.any(np.abs(self.model.command - self.model.position) > FOLLOWING_ERROR * span):
            f |= protocol.FLAG_FOLLOWING
        return f

    def state_code(self) -> int:
        if self.estop:
            return protocol.STATE_STOPPED
        if self.following and not self.watchdog:
            return protocol.STATE_OPERATIONAL
        return protocol.STATE_PRE_OPERATIONAL

    def answer(self, tick: int, rejected: int, noise: np.ndarray | None = None) -> list:
        """The answer to SYNC `tick`: STATUS (then LIMIT clears), a pending
        NACK, and a HEARTBEAT when due (BOOT in the first answer).
        rejected: frames the link refused before their header could be believed."""
        state = self.state_code()
        mine = self.counters.stale + self.counters.refused
        out = [protocol.Status(node=self.node, tick=tick, flags=self.flags(), state=state,
                               rejected=(rejected + mine) % 65536,
                               seq_gaps=self.counters.seq_gaps % 65536,
                               positions=tuple(int(c) for c in self.actual_counts(noise)))]
        self.limited = False
        if self.pending_nack is not None:
            out.append(self.pending_nack)
            self.pending_nack = None
        self.heartbeat_due -= 1
        if self.heartbeat_state is None:
            state = protocol.STATE_BOOT
        if state != self.heartbeat_state or self.heartbeat_due <= 0:
            out.append(protocol.Heartbeat(self.node, state, self.heartbeats % (1 << 32)))
            self.heartbeats += 1
            self.heartbeat_state, self.heartbeat_due = state, HEARTBEAT_TICKS
        return out

    def actual_counts(self, noise: np.ndarray | None = None) -> np.ndarray:
        """Actual positions [counts] per channel, as the encoders report them."""
        x = self.offset + self.scale * self.model.position
        if noise is not None:
            x = x + noise
        return np.rint(x).astype(np.int64)
