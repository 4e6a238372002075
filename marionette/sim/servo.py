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
the last tick. At every fine step the lag's step is inverted so that the
drive lands on that braking profile plus its offset, at the same point of
the tick before the brake, from the line the profile extends back: its
wobble within a tick, from holding each setpoint. The measure compares
positions a tick apart, so the kept wobble cancels from it and the
measure sees the profile's own acceleration, at most the limit (where it
reaches back before the brake, at most that or what the motion before
had); once the profile has ended, the wobble fades out over FADE_TICKS.

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
FADE_TICKS = 5          # quick stop: ticks over which the drive's wobble fades at rest


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
        self._brake_y = x0.copy()                # quick stop: the profile's start [unit],
        self._brake_v = np.zeros(n)              # ... its velocity there [unit/s],
        self._brake_age = np.zeros(n, dtype=int) # ... fine steps since then,
        self._brake_w = np.zeros((self.sample_steps, n))  # ... the wobble of the tick before [unit]
        self._input = x0.copy()                  # the lag's input in the last fine step [unit]

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
        per_tick = self.sample_steps
        T = per_tick * self.step                                            # [s]
        v = np.clip((self.position - self._back(per_tick)) / T, -self.max_speed, self.max_speed)
        self._brake_y[new] = self.position[new]
        self._brake_v[new] = v[new]
        self._brake_age[new] = 0
        # the last tick's positions off the line the profile extends back
        # (row i: i + 1 fine steps into that tick)
        back = np.arange(per_tick - 1, -1, -1)                              # [fine steps]
        past = np.array([self._back(int(m)) for m in back])                 # [unit]
        line = self.position - np.outer(back * self.step, v)                # [unit]
        self._brake_w[:, new] = (past - line)[:, new]
        self.braking[:] = True

    def _brake_goal(self) -> np.ndarray:
        """Where the quick stop puts each drive after this fine step [unit]:
        its braking profile, which ends at y + v|v| / (2 max_accel), plus
        its wobble at the same point of the tick before the brake (module
        docstring)."""
        T = self.sample_steps * self.step                                   # [s]
        t = self._brake_age * self.step                                     # [s] since the brake
        v, a = self._brake_v, self.max_accel
        end = np.abs(v) / a                                                 # [s] braking ends
        s = np.minimum(t, end)                                              # [s]
        profile = np.clip(self._brake_y + v * s - np.sign(v) * a * s * s / 2, self.lower, self.upper)
        # from a tick after the profile's end (the last comparisons with the
        # braking done), the offset fades over FADE_TICKS (a half cosine)
        fade = np.clip((t - end - T) / (FADE_TICKS * T), 0.0, 1.0)
        phase = (self._brake_age - 1) % self.sample_steps                   # row of the tick before
        wobble = self._brake_w[phase, np.arange(len(self.axes))]
        return profile + wobble * (1 + np.cos(np.pi * fade)) / 2

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
                self._steps += rest
                break
            self._head = (self._head + 1) % depth
            self._line[self._head] = self.command
            delayed = self._line[(self._head - self.delay_steps) % depth, cols]
            if self.braking.any():
                # the lag's step inverted: the input that moves the drive
                # onto the quick stop's goal in this step
                self._brake_age += 1
                steer = self.position + (self._brake_goal() - self.position) / self._alpha
                delayed = np.where(self.braking, steer, delayed)
                self.command = np.where(self.braking, steer, self.command)
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
