"""ArrivalClock (marionette/sim/arrival.py): frames read late by the
simulator are placed by the host's tick clock within the window they may
have arrived in; frames read on time keep their read time."""
import numpy as np

from marionette import protocol
from marionette.sim.arrival import ArrivalClock

T = 0.02


def frames(ticks):
    out = []
    for k in ticks:
        out += [protocol.Sync(k), protocol.Setpoints(k, ((1, 0, 0),))]
    return out


def test_read_on_time_keeps_the_read_time_and_learns_the_tick_clock():
    rng = np.random.default_rng(1)
    clock = ArrivalClock(T)
    for k in range(50):
        now = 1.0 + k * T + rng.uniform(0.0005, 0.004)       # transport and wake-up delay [s]
        assert clock.times(frames([k]), now, now) == [now, now]
    assert 0.9995 <= clock.offset <= 1.0006


def test_a_backlog_read_late_is_spread_by_the_tick_clock_within_its_window():
    rng = np.random.default_rng(2)
    for case in range(50):
        clock = ArrivalClock(T)
        base = rng.uniform(0, 100)
        for k in range(20):                                    # on time: learn the clock
            clock.times(frames([k]), base + k * T + 0.001, base + k * T + 0.001)
        stall = rng.uniform(0.1, 1.0)                          # [s] this process was off the CPU
        since = base + 19 * T + 0.001
        ticks = range(20, 20 + int(stall / T))
        now = since + stall
        times = clock.times(frames(ticks), since, now)
        expected = [min(max(base + k * T + 0.001, since), now) for k in ticks for _ in (0, 1)]
        assert np.allclose(times, expected, rtol=0, atol=1e-9), case
        assert all(b >= a for a, b in zip(times, times[1:]))  # never backwards


def test_a_host_that_catches_up_late_is_not_moved_before_the_window():
    clock = ArrivalClock(T)
    for k in range(10):
        clock.times(frames([k]), 1.0 + k * T, 1.0 + k * T)
    # ticks 10.. sent 0.3 s late (the host stalled); read late too: never before since
    times = clock.times(frames(range(10, 15)), 1.5, 1.6)
    assert min(times) >= 1.5 and max(times) <= 1.6


def test_a_restarted_host_resets_the_tick_clock_and_frames_without_a_tick_follow_the_last():
    clock = ArrivalClock(T)
    for k in range(100, 110):
        clock.times(frames([k]), 5.0 + k * T, 5.0 + k * T)
    times = clock.times(frames([0]) + [protocol.Estop(protocol.BROADCAST)], 20.0, 20.0)
    assert times == [20.0, 20.0, 20.0]
    assert clock.offset == 20.0
