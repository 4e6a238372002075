"""When did a frame reach the simulated node? The simulator's own answer
when it was late itself.

A node's firmware handles each frame as it arrives. The simulator is a
process on a shared machine: when the scheduler keeps it off the CPU for
a few hundred ms, the host's frames wait in the pty or socket and are read
together, and if each were timed by the moment it is read, the simulated
watchdog would trip for a gap that the host never left.

The server (server.py) knows when it last looked at its input and how
long it asked select to wait. Input read much later than that (LATE_S
beyond the wait) was read late by this process: it arrived at some time
in [since, now], since being that last look, and a frame with a tick
counter (SYNC, SETPOINT) is placed there where the host's tick clock puts
it: the earliest lateness seen so far (read time minus tick times period)
plus its tick times period. Input read on time is timed as read (since =
now), so a host that falls silent trips the watchdog as it should. A
frame without a tick counter comes with the one before it in the same
read, or at `now` when it is the first. Times never go backwards.
"""
from __future__ import annotations


class ArrivalClock:
    def __init__(self, period: float):
        self.period = period                # the host's tick [s]
        self.offset: float | None = None    # earliest (read time - tick * period) seen [s]
        self.last_tick: int | None = None
        self.last_time = float("-inf")      # the last frame's arrival [s]

    def times(self, messages, since: float, now: float) -> list[float]:
        """Arrival times [s] of messages read together at now [s], waited for since [s]."""
        out = []
        for m in messages:
            tick = getattr(m, "tick", None)
            if tick is None:
                t = out[-1] if out else now
            else:
                seen = now - tick * self.period
                if self.offset is None or (self.last_tick is not None and tick < self.last_tick):
                    self.offset = seen              # the first frame, or the host started again
                self.offset = min(self.offset, seen)
                self.last_tick = tick
                t = min(max(self.offset + tick * self.period, since), now)
            t = max(t, self.last_time)
            self.last_time = t
            out.append(t)
        return out
