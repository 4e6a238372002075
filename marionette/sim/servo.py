"""The behaviour model of simulated servos: what a real drive does with the
setpoints it is sent.

Per channel: the setpoint is held until the next one comes (zero-order
hold), delayed by a pure dead time, and followed through a first-order lag
whose speed and acceleration are limited, inside the position limits. The
model is integrated at a fine internal step (1 ms by default), vectorised
over the channels.

A figure's `dead_time` is what identification measures at the tick: it
includes the half tick that holding each setpoint adds. The servo itself
therefore waits `dead_time - tick_period / 2` (never less than zero).
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from marionette.config import AxisConfig

FINE_STEP = 0.001       # internal integration step [s]


class ServoModel:
    """Simulated servos for a list of axes, advanced in fine steps."""

    def __init__(self, axes: Sequence[AxisConfig], tick_period: float, step: float = FINE_STEP,
                 start: Sequence[float] | None = None):
        self.axes = tuple(axes)
        self.step = float(step)                                              # [s]
        n = len(self.axes)
        lag = np.array([a.time_constant for a in self.axes])                 # [s]
        # exact discretisation of the lag when no limit acts
        self._alpha = np.where(lag > 0, 1.0 - np.exp(-self.step / np.maximum(lag, 1e-300)), 1.0)
        self.max_speed = np.array([a.max_speed for a in self.axes])          # [unit/s]
        self.max_accel = np.array([a.max_accel for a in self.axes])          # [unit/s^2]
        self.lower = np.array([a.min for a in self.axes])                    # [unit]
        self.upper = np.array([a.max for a in self.axes])                    # [unit]
        servo_dead = np.maximum(0.0, np.array([a.dead_time for a in self.axes]) - tick_period / 2)
        self.delay_steps = np.rint(servo_dead / self.step).astype(int)       # [steps]
        x0 = np.array([a.home for a in self.axes] if start is None else start, dtype=float)
        self.position = x0.copy()                                            # [unit]
        self.velocity = np.zeros(n)                                          # [unit/s]
        self.command = x0.copy()                                             # held setpoint [unit]
        # delay line: the command each channel saw in its last delay_steps steps
        depth = int(self.delay_steps.max()) + 1
        self._line = np.tile(x0, (depth, 1))
        self._head = 0
        self.time = 0.0                                                      # model time [s]

    def set_command(self, command) -> None:
        """Hold these setpoints [unit] from now on (NaN keeps a channel's old one)."""
        c = np.asarray(command, dtype=float)
        self.command = np.where(np.isnan(c), self.command, c)

    def set_channel(self, j: int, value: float) -> None:
        self.command[j] = value

    def advance(self, seconds: float) -> None:
        """Integrate the model forward by seconds [s] (whole fine steps)."""
        steps = int(round(seconds / self.step))
        depth = self._line.shape[0]
        cols = np.arange(len(self.axes))
        for _ in range(steps):
            self._head = (self._head + 1) % depth
            self._line[self._head] = self.command
            delayed = self._line[(self._head - self.delay_steps) % depth, cols]
            wanted = self._alpha * (delayed - self.position) / self.step     # [unit/s]
            wanted = np.clip(wanted, -self.max_speed, self.max_speed)
            dv = np.clip(wanted - self.velocity, -self.max_accel * self.step, self.max_accel * self.step)
            self.velocity += dv
            self.position += self.velocity * self.step
            low, high = self.position < self.lower, self.position > self.upper
            self.position = np.clip(self.position, self.lower, self.upper)
            self.velocity[low | high] = 0.0
        self.time += steps * self.step

    def advance_to(self, t: float) -> None:
        """Integrate up to model time t [s]."""
        if t > self.time:
            self.advance(t - self.time)
