"""The behaviour model of simulated servos: what a real drive does with the
setpoints it is sent.

Per channel: the setpoint is held until the next one comes (zero-order
hold), delayed by a pure dead time, and followed through a first-order lag
whose speed and acceleration are limited, inside the position limits. The
model is integrated at a fine internal step (1 ms by default), vectorised
over the channels.

Two modes. By default (clip_accel=True) the drive also clips each step's
change of velocity to the axis's acceleration limit, as a drive with its own
acceleration ramp would. With clip_accel=False it does not: the model is
the bare behaviour model (dead time + first-order lag, only speed and
position limits), so a command stream that asks for more than the axis
can do shows up as a physical acceleration above the limit. Either way
`peak_accel` is the largest physical acceleration seen per axis [unit/s^2],
at the scale of a tick: (x(t) - 2 x(t - T) + x(t - 2T)) / T^2 at every
fine step t. The lag's velocity jumps at each held setpoint, so a finer
measure would see the staircase, not the motion. A command stream whose own acceleration
is within the limit gives a physical one within it (the lag, sampled at the
tick, averages past commands with non-negative weights).

`brake()` is a drive's own quick stop (the node's e-stop and watchdog):
from that step on the setpoints, also those still inside the dead time,
are ignored. The stop point is where the drive itself comes to rest
braking at its acceleration limit from its position and its velocity over
the last tick; the drive is steered along that braking profile by
inverting its lag: the lag's input goes on as a staircase in the phase of
the setpoints it replaces, each step the input that, held until the next,
brings the drive onto the profile. The first step comes at once and is
held only until the next one is due. Braking the input instead of the
drive, as before, let the drive, lagging tau * v behind it, pass its own
stop point by that much.

At a position limit the drive stops dead: the position is clipped and any
velocity pointing out of the range is zeroed, at both limits alike.

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
                 start: Sequence[float] | None = None, clip_accel: bool = True):
        self.axes = tuple(axes)
        self.clip_accel = bool(clip_accel)
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
        self.braking = np.zeros(n, dtype=bool)   # quick stop in progress or done (brake())
        # physical acceleration at the scale of a tick, from the positions
        # of the last 2 ticks (a ring of fine steps)
        self.sample_steps = max(1, int(round(tick_period / self.step)))      # [steps]
        self.peak_accel = np.zeros(n)                                        # [unit/s^2]
        self._past = np.tile(x0, (2 * self.sample_steps + 1, 1))             # [unit]
        self._steps = 0                          # fine steps taken
        self._brake_x = x0.copy()                # quick stop: the lag's input [unit]
        self._brake_y = x0.copy()                # ... its profile: start [unit],
        self._brake_v = np.zeros(n)              # ... velocity there [unit/s],
        self._brake_age = np.zeros(n, dtype=int) # ... fine steps since its start
        self._brake_next = np.zeros(n, dtype=int)   # fine steps until the input's next step
        self._input = x0.copy()                  # the lag's input in the last fine step [unit]
        self._held = np.zeros(n, dtype=int)      # fine steps it has been held

    def reset_peak(self) -> None:
        """Forget the peak acceleration seen so far."""
        self.peak_accel[:] = 0.0

    def set_command(self, command) -> None:
        """Hold these setpoints [unit] from now on (NaN keeps a channel's old one)."""
        c = np.asarray(command, dtype=float)
        self.command = np.where(np.isnan(c), self.command, c)

    def set_channel(self, j: int, value: float) -> None:
        self.command[j] = value

    def _back(self, steps: int) -> np.ndarray:
        """Positions [unit] this many fine steps ago (at most 2 ticks)."""
        return self._past[(self._steps - steps) % self._past.shape[0]]

    def brake(self) -> None:
        """Quick stop: ignore setpoints (also those inside the dead time);
        brake the drive from where it is, at its velocity over the last tick
        [unit/s], at the acceleration limit to rest, and hold there (until
        release())."""
        new = ~self.braking
        T = self.sample_steps * self.step                                   # [s]
        v = np.clip((self.position - self._back(self.sample_steps)) / T, -self.max_speed, self.max_speed)
        # the input steps in the phase of the setpoints it replaces: a step
        # in mid-tick would show in the drive's acceleration over a tick
        self._brake_next[new] = (self.sample_steps - self._held % self.sample_steps)[new]
        # the profile starts on the drive's motion as seen at those steps
        # (its position at the last step, on at v), not on its wobble
        # within the tick, which would show the same way
        since = self.sample_steps - self._brake_next                        # [fine steps]
        at_step = self._past[(self._steps - since) % self._past.shape[0], np.arange(len(self.axes))]
        self._brake_y[new] = (at_step + v * since * self.step)[new]
        self._brake_v[new] = v[new]
        self._brake_age[new] = 0
        self.braking[:] = True
        self._steer(new)

    def _steer(self, due: np.ndarray) -> None:
        """The next step of the quick stop's input for the drives due: the
        input that, held until the step after, brings each onto its braking
        profile, which ends at y + v|v| / (2 max_accel)."""
        for j in np.flatnonzero(due):
            n = int(self._brake_next[j])                                     # [fine steps]
            y, v, a = self._brake_y[j], self._brake_v[j], self.max_accel[j]
            t = min((self._brake_age[j] + n) * self.step, abs(v) / a)        # [s], braking ends
            goal = min(max(y + v * t - np.sign(v) * a * t * t / 2, self.lower[j]), self.upper[j])
            self._brake_x[j] = self._hold_input(j, goal, n)

    def _hold_input(self, j: int, goal: float, n: int) -> float:
        """The input [unit] that, held n fine steps, moves drive j from its
        position to goal [unit]: the model's step inverted. Each step closes
        alpha of the gap, at most vmax * step; a goal beyond n such steps
        gets the input that runs the drive at top speed."""
        y = self.position[j]
        d, sign = abs(goal - y), (1.0 if goal >= y else -1.0)               # [unit]
        top = self.max_speed[j] * self.step                                 # [unit] per step
        keep = 1.0 - self._alpha[j]                                         # of an unclipped gap
        clip = top / self._alpha[j]                                         # wider gaps move at top
        for m in range(n):                  # m steps at top speed, then the lag's decay
            gap = m * top + (d - m * top) / (1.0 - keep ** (n - m))
            if gap - m * top <= clip:
                return y + sign * gap
        return y + sign * (clip + n * top)  # every step at top speed

    def release(self) -> None:
        """End a quick stop: hold the present position until new setpoints come."""
        self.braking[:] = False
        self.command = self.position.copy()
        self._line[:] = self.position
        self._input[:] = self.position

    def advance(self, seconds: float) -> None:
        """Integrate the model forward by seconds [s] (whole fine steps)."""
        steps = int(round(seconds / self.step))
        depth = self._line.shape[0]
        cols = np.arange(len(self.axes))
        for done in range(steps):
            if not self.velocity.any() and self._resting():
                # every further step would leave the state as it is: skip them
                # (idle drives cost a simulator a quarter of a core, which on
                # a busy machine made its answers late)
                rest = steps - done
                self._head = (self._head + rest) % depth
                self._held = self._held + rest
                self._steps += rest
                break
            self._head = (self._head + 1) % depth
            self._line[self._head] = self.command
            delayed = self._line[(self._head - self.delay_steps) % depth, cols]
            if self.braking.any():
                self._brake_age += 1
                self._brake_next -= 1
                delayed = np.where(self.braking, self._brake_x, delayed)
            self._held = np.where(delayed == self._input, self._held + 1, 1)
            self._input = delayed
            wanted = self._alpha * (delayed - self.position) / self.step     # [unit/s]
            wanted = np.clip(wanted, -self.max_speed, self.max_speed)
            dv = wanted - self.velocity
            if self.clip_accel:
                dv = np.clip(dv, -self.max_accel * self.step, self.max_accel * self.step)
            self.velocity += dv
            self.position += self.velocity * self.step
            self.position = np.clip(self.position, self.lower, self.upper)
            # stopped dead at a limit: no velocity out of the range (both alike)
            out = ((self.position <= self.lower) & (self.velocity < 0)) | \
                  ((self.position >= self.upper) & (self.velocity > 0))
            self.velocity[out] = 0.0
            if self.braking.any():
                due = self.braking & (self._brake_next <= 0)
                self._brake_next[due] = self.sample_steps
                self._steer(due)
            self.command = np.where(self.braking, self._brake_x, self.command)
            self._steps += 1
            self._past[self._steps % self._past.shape[0]] = self.position
            T = self.sample_steps * self.step                                # [s]
            a = np.abs(self.position - 2 * self._back(self.sample_steps)
                       + self._back(2 * self.sample_steps)) / (T * T)
            np.maximum(self.peak_accel, a, out=self.peak_accel)
        self.time += steps * self.step

    def _resting(self) -> bool:
        """At a fixed point: not braking, at rest exactly where it is
        commanded, with every delayed and past value the same."""
        return (not self.braking.any() and np.array_equal(self.position, self.command)
                and (self._line == self.command).all() and (self._input == self.command).all()
                and (self._past == self.position).all())

    def advance_to(self, t: float) -> None:
        """Integrate up to model time t [s]."""
        if t > self.time:
            self.advance(t - self.time)
