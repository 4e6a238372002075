"""All simulated servo nodes of a figure, fed decoded protocol messages.

This is the in-process simulator: the serial and CAN front ends of
`marionette sim` feed it, and unit tests can feed it directly. Model time
is whatever the caller passes [s]: wall-clock time in the simulator
process, tick * period for a virtual clock.
"""
from __future__ import annotations

from collections import defaultdict

import numpy as np

from marionette import protocol
from marionette.config import FigureConfig
from marionette.music.bands import BandMeter
from marionette.music.feature import LoudnessMeter, mono
from marionette.sim.faults import Faults
from marionette.sim.node import DEFAULT_WATCHDOG_TICKS, SimNode


class SimFigure:
    def __init__(self, config: FigureConfig, faults: Faults | None = None,
                 watchdog_ticks: int = DEFAULT_WATCHDOG_TICKS, trace: bool = False,
                 music: tuple[np.ndarray, float] | None = None, music_node: int | None = None,
                 clip_accel: bool = True, music_bands: bool = True):
        """clip_accel: False for drives that do not clip acceleration
        (ServoModel), so that a command stream asking too much shows in
        peak_accel(). music: (samples, sample rate [Hz]) of a recording that plays from
        model time 0; node music_node measures it and answers each SYNC with
        a LOUDNESS of the tick period just before that SYNC: its loudness
        and, with music_bands, its band loudness (BandMeter), else the
        loudness alone (a one-band node)."""
        self.config = config
        self.faults = faults or Faults()
        by_node = defaultdict(list)
        for a in config.axes:
            by_node[a.node].append(a)
        self.nodes = {n: SimNode(n, axes, config.tick_period, watchdog_ticks, clip_accel)
                      for n, axes in sorted(by_node.items())}
        # where each figure axis lives: (node, index on that node)
        self._where = [(a.node, self.nodes[a.node].channels.index(a.channel)) for a in config.axes]
        self.messages = 0                   # messages taken
        self.music = None
        if music is not None:
            samples, rate = music
            self.music = mono(samples)                                # [full scale]
            self._meter = LoudnessMeter(rate, config.tick_period)
            self._band_meter = BandMeter(rate, config.tick_period) if music_bands else None
        self.music_node = music_node
        self._music_sent = 0                # LOUDNESS frames sent
        # (SYNC arrival [s], tick, positions [unit] in figure order, their model time [s])
        self.trace = [] if trace else None

    def positions(self) -> np.ndarray:
        """Actual positions [unit] of the figure's axes, in configuration order."""
        return np.array([self.nodes[n].model.position[j] for n, j in self._where])

    def peak_accel(self) -> np.ndarray:
        """Largest physical acceleration so far [unit/s^2] per axis, in
        configuration order (ServoModel.peak_accel)."""
        return np.array([self.nodes[n].model.peak_accel[j] for n, j in self._where])

    @property
    def time(self) -> float:
        """Model time the drives have run to [s]."""
        return min(node.model.time for node in self.nodes.values())

    def advance_to(self, t: float) -> None:
        for node in self.nodes.values():
            node.advance_to(t)

    def handle(self, message, t: float, rejected: int = 0) -> list:
        """Act on one message (or protocol.Refused frame) at model time t [s];
        returns the answers (messages). rejected: frames the link refused so
        far before their header could be believed (every node counts them)."""
        self.messages += 1
        kind = type(message)
        if kind is protocol.Sync:
            return self._on_sync(message, t, rejected)
        if kind is protocol.Setpoints:
            accepted = {}
            for node, channel, counts in message.entries:
                sim = self._listening(node)
                if sim is None:
                    continue
                if node not in accepted:
                    accepted[node] = sim.on_tick(message.tick)
                if accepted[node]:
                    sim.on_setpoint(message.tick, channel, counts, t)
            return []
        if kind in (protocol.Estop, protocol.EstopRelease):
            for sim in self._addressed(message.node):
                (sim.on_estop if kind is protocol.Estop else sim.on_release)(t)
            return []
        if kind is protocol.Config:
            return [a for sim in self._addressed(message.node) for a in sim.on_config(message, t)]
        if kind is protocol.Refused and not message.type & protocol.FROM_NODE:
            # another node's frame is none of ours (SPEC.md 6, Receiving)
            alone = message.node != protocol.BROADCAST
            return [a for sim in self._addressed(message.node) for a in sim.on_refused(message, alone)]
        return []                       # what nodes send, seen on a shared line

    def _listening(self, node: int) -> SimNode | None:
        if node in self.faults.silent:
            return None
        return self.nodes.get(node)

    def _addressed(self, node: int) -> list[SimNode]:
        if node == protocol.BROADCAST:
            return [s for n, s in self.nodes.items() if n not in self.faults.silent]
        sim = self._listening(node)
        return [] if sim is None else [sim]

    def _on_sync(self, sync, t: float, rejected: int) -> list:
        self.advance_to(t)
        if self.trace is not None:
            model_time = next(iter(self.nodes.values())).model.time     # whole internal steps [s]
            self.trace.append((t, sync.tick, self.positions(), model_time))
        answers = []
        for sim in self._addressed(protocol.BROADCAST):
            sim.on_sync(sync.tick)
            if sync.poll in (protocol.BROADCAST, sim.node):
                answers += sim.answer(sync.tick, rejected, self.faults.noise(len(sim.channels)))
        if self.music is not None and self.music_node not in self.faults.silent:
            frame = self._music_before(t)
            if frame is not None:
                answers.append(protocol.Loudness(self.music_node, self._music_sent, *frame))
                self._music_sent += 1
        return answers

    def _music_before(self, t: float) -> tuple | None:
        """Loudness of the music in the tick period before model time t [s]
        [full scale], and its band loudness (None for a one-band node); None
        before the music has played a whole period or after its end.
        Measured at the SYNC so that its age at the host is fixed (one period
        plus the answer's way), whatever the phase between the host's ticks
        and the start of the music."""
        rate, n = self._meter.sample_rate, self._meter.frame_len
        start = int(np.floor((t - self.config.tick_period) * rate))     # [samples]
        if start < 0 or start + n > len(self.music):
            return None
        value = float(self._meter.frame_loudness(self.music[start:start + n])[0])
        if self._band_meter is None:
            return value, None
        window = self.music[max(0, start + n - self._band_meter.window_len):start + n]
        window = np.pad(window, (self._band_meter.window_len - len(window), 0))   # silence before the music
        return value, tuple(self._band_meter.window_bands(window)[0])

    def trace_arrays(self) -> dict:
        """The trace as arrays: time (SYNC arrival) [s], tick, positions [unit]
        (ticks x axes), model_time (of the positions, whole internal steps) [s]."""
        if not self.trace:
            return {"time": np.zeros(0), "tick": np.zeros(0, np.int64),
                    "positions": np.zeros((0, len(self.config.axes))), "model_time": np.zeros(0)}
        t, k, x, m = zip(*self.trace)
        return {"time": np.array(t), "tick": np.array(k, np.int64), "positions": np.array(x),
                "model_time": np.array(m)}
