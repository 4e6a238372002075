"""The simulated servos' behaviour model: exact where no limit acts, and the
limits hold in random cases."""
from dataclasses import replace

import numpy as np
import pytest

from conftest import make_figure
from marionette.sim.servo import ServoModel

T = 0.02        # tick [s]


def test_step_response_is_dead_time_then_first_order_lag():
    dead, tau = 0.05, 0.1                               # servo's own dead time, lag [s]
    config = make_figure(1, dead_time=dead + T / 2, time_constant=tau,
                         max_speed=1e6, max_accel=1e9)
    m = ServoModel(config.axes, T, start=[0.0])
    m.set_command([0.5])
    times, xs = [], []
    for _ in range(400):
        m.advance(0.001)
        times.append(m.time)
        xs.append(m.position[0])
    t, x = np.array(times), np.array(xs)
    # the command enters the lag at the step the delay line releases it
    expected = np.where(t < dead + 0.001 - 1e-12, 0.0,
                        0.5 * (1 - np.exp(-(np.round((t - dead) / 0.001)) * 0.001 / tau)))
    np.testing.assert_allclose(x, expected, atol=1e-12)


def test_limits_hold_in_random_cases():
    rng = np.random.default_rng(20261122)
    for case in range(40):
        speed, accel = rng.uniform(0.2, 3), rng.uniform(1, 30)
        config = make_figure(2, max_speed=speed, max_accel=accel,
                             dead_time=rng.uniform(0.01, 0.1), time_constant=rng.uniform(0, 0.2))
        lo, hi = config.axes[0].min, config.axes[0].max
        m = ServoModel(config.axes, T)
        x_prev, v_prev = m.position.copy(), m.velocity.copy()
        for k in range(300):
            if k % 7 == 0:      # wild setpoints, outside the limits too
                m.set_command(rng.uniform(lo - 1, hi + 1, 2))
            m.advance(0.001)
            v = (m.position - x_prev) / 0.001
            assert np.all(m.position >= lo - 1e-12) and np.all(m.position <= hi + 1e-12), case
            assert np.all(np.abs(m.velocity) <= speed * (1 + 1e-12)), case
            # a clamp at a position limit may stop an axis at once; elsewhere accel holds
            inside = (m.position > lo) & (m.position < hi)
            assert np.all(np.abs(m.velocity - v_prev)[inside] <= accel * 0.001 * (1 + 1e-9)), case
            assert np.all(np.abs(v) <= speed * (1 + 1e-9)), case
            x_prev, v_prev = m.position.copy(), m.velocity.copy()


def test_nan_command_keeps_the_old_setpoint():
    config = make_figure(2)
    m = ServoModel(config.axes, T, start=[0.1, 0.2])
    m.set_command([0.3, np.nan])
    assert m.command.tolist() == [0.3, 0.2]


@pytest.mark.parametrize("dead", [0.0, 0.005])
def test_dead_time_shorter_than_half_a_tick_is_zero(dead):
    config = make_figure(1, dead_time=dead)
    assert ServoModel(config.axes, T).delay_steps.tolist() == [0]


def test_both_limits_alike_stop_dead_and_are_left_at_once():
    """Driven into either limit (and mirrored, the other), with or without
    acceleration clipping: no velocity out of the range while clipped, and
    after a command back the axis leaves the limit after its dead time, the
    same step at both limits. The 40 cases' 80 drives run side by side as
    the channels of one model per clipping mode (the model is vectorised
    over channels, each with its own limits, dead time and lag): each one
    steps as it would alone."""
    rng = np.random.default_rng(20261201)
    drives = {False: [], True: []}      # clip -> [(case, side, axis, edge, sign, command)]
    for case in range(40):
        clip = bool(case % 2)
        lo, hi = rng.uniform(-2, 0.5), rng.uniform(0.6, 3)
        config = make_figure(1, min=lo, max=hi, home=(lo + hi) / 2, max_speed=rng.uniform(0.3, 3),
                             max_accel=rng.uniform(1, 30), dead_time=rng.uniform(0.01, 0.1),
                             time_constant=rng.uniform(0.01, 0.2))
        for side, edge, sign in (("upper", hi, 1.0), ("lower", lo, -1.0)):
            drives[clip].append((case, side, config.axes[0], edge, sign,
                                 edge + sign * rng.uniform(0.1, 1), edge - sign * 0.3 * (hi - lo)))
    for clip, rows in drives.items():
        cases, sides, axes, edge, sign, into, back = zip(*rows)
        edge, sign = np.array(edge), np.array(sign)
        m = ServoModel(axes, T, clip_accel=clip)
        m.set_command(into)
        for _ in range(4000):
            m.advance(0.001)
            at = m.position == edge
            bad = at & (sign * m.velocity > 0)
            assert not bad.any(), [(cases[j], sides[j], m.velocity[j]) for j in np.flatnonzero(bad)]
        assert np.all(m.position == edge), [(cases[j], sides[j]) for j in np.flatnonzero(m.position != edge)]
        m.set_command(back)
        left = np.zeros(len(rows), dtype=int)           # fine steps until each leaves its limit
        for k in range(1, 1000):
            m.advance(0.001)
            left[(left == 0) & (m.position != edge)] = k
            if left.all():
                break
        for j in range(0, len(rows), 2):                # (upper, lower) of one case
            assert sides[j:j + 2] == ("upper", "lower")
            assert 0 < left[j] == left[j + 1] <= m.delay_steps[j] + 1, \
                (cases[j], {"upper": left[j], "lower": left[j + 1]})


def test_without_acceleration_clipping_a_jump_shows_in_the_peak():
    config = make_figure(1, max_speed=2.0, max_accel=20.0)
    for clip, expect_violation in ((True, False), (False, True)):
        m = ServoModel(config.axes, T, start=[0.0], clip_accel=clip)
        m.set_command([0.5])                    # a jump of the setpoint
        m.advance(1.0)
        assert (m.peak_accel[0] > 20.0 * 1.02) == expect_violation, (clip, m.peak_accel)
    # a stream within the limit stays within it, also unclipped
    m = ServoModel(config.axes, T, start=[0.0], clip_accel=False)
    t = np.arange(200) * T
    for x in 0.4 * np.sin(2 * np.pi * 0.5 * t) * np.minimum(1, t):       # 0.5 Hz, faded in
        m.set_command([x])
        m.advance(T)
    assert 0 < m.peak_accel[0] <= 20.0, m.peak_accel


def test_resting_drives_skip_their_steps_exactly(figure):
    """A drive at rest where it is commanded skips its fine steps in one go
    (an idle simulator then costs nothing); the result is what stepping
    every millisecond gives, through rests, moves, a quick stop and release."""
    fast = ServoModel(figure.axes, T)
    slow = ServoModel(figure.axes, T)
    slow._resting = lambda: False                   # steps every millisecond
    rng = np.random.default_rng(7)
    lo, hi = np.array([a.min for a in figure.axes]), np.array([a.max for a in figure.axes])
    home = np.array([a.home for a in figure.axes])
    for k in range(12):
        for m in (fast, slow):
            if k in (2, 6):
                m.set_command(home + (hi - home) * rng.uniform(0, 0.3, len(home)) if m is fast else target)
            if k == 4:
                m.brake()
            if k == 5:
                m.release()
            m.advance(0.35)
            if m is fast and k in (2, 6):
                target = fast.command.copy()
        np.testing.assert_array_equal(fast.position, slow.position)
        np.testing.assert_array_equal(fast.velocity, slow.velocity)
        np.testing.assert_array_equal(fast.peak_accel, slow.peak_accel)
        assert fast._steps == slow._steps and fast.time == slow.time
        if k == 1:
            assert fast._resting()                  # at home and at rest: the skip is taken


def test_quick_stop_from_steady_motion_brakes_at_the_limit_onto_its_stop_point():
    """A drive cruising at a steady speed, braked at phases across the tick
    of its setpoints, comes to rest where braking at its limit from its
    motion ends, passing it by no more than its wobble within a tick (0.1 %
    of its range), and decelerates within its limit over every tick."""
    axis = make_figure(1, time_constant=0.05, dead_time=0.03, max_speed=2.0, max_accel=12.0).axes[0]
    axes = [axis, replace(axis, time_constant=0.12, dead_time=0.065)]      # steps in phase, and not
    a = np.array([ax.max_accel for ax in axes])
    span = axis.max - axis.min                                              # [unit]
    for speed in (0.5, 1.0, 1.6):                                           # [unit/s]
        for phase in range(0, 20, 3):                                       # [fine steps]
            m = ServoModel(axes, T, start=[-0.9] * 2, clip_accel=False)
            for k in range(25):                                             # at speed from tick 5
                m.set_command(-0.9 + speed * T * np.maximum(0, k - 4) * np.ones(2))
                m.advance(T)
            m.reset_peak()
            m.set_command(-0.9 + speed * T * 21 * np.ones(2))
            m.advance(phase * m.step)
            v = (m.position - m._back(m.sample_steps)) / T
            stop = m.position + v * np.abs(v) / (2 * a)
            m.brake()
            xs = []
            for _ in range(30):
                m.advance(T)
                xs.append(m.position.copy())
            assert np.abs(xs[-1] - stop).max() <= 1e-12 * span, (speed, phase, xs[-1] - stop)
            assert np.max(np.array(xs) - stop) <= 1e-3 * span, (speed, phase)
            assert xs[-1] == pytest.approx(xs[-2], abs=1e-12)               # at rest
            assert np.all(m.peak_accel <= a * (1 + 1e-9)), (speed, phase, m.peak_accel / a)


def test_quick_stops_of_random_drives_brake_within_the_limit_onto_their_stop_point():
    """Drives of random lag (none too), dead time and limits, moving along
    random sinusoids inside their position limits, braked at a random fine
    step: over a tick wholly after the brake they accelerate at most at the
    limit; reaching back before it, at most at the larger of the limit and
    the motion before; they pass the stop point by at most 1 % of the range
    and rest on it."""
    rng = np.random.default_rng(20261202)
    for case in range(60):
        vmax = rng.uniform(0.5, 3)                                          # [unit/s]
        amax = rng.uniform(max(2, vmax ** 2), 30)                           # [unit/s^2]: stops inside
        tau = 0.0 if case % 8 == 0 else rng.uniform(0.005, 0.25)           # [s]
        config = make_figure(1, max_speed=vmax, max_accel=amax, time_constant=tau,
                             dead_time=rng.uniform(0.01, 0.1))
        m = ServoModel(config.axes, T, start=[0.0], clip_accel=False)
        per_tick = m.sample_steps
        f = rng.uniform(0.2, 2)                                             # [Hz]
        amp = min(0.2, 0.8 * vmax / (2 * np.pi * f), 0.8 * amax / (2 * np.pi * f) ** 2)  # [unit]
        phase = rng.uniform(0, 2 * np.pi)
        xs = [m.position[0]]
        ticks, into = int(rng.integers(20, 60)), int(rng.integers(0, per_tick))
        for k in range(ticks + 1):                                          # braked in the last
            m.set_command([amp * (np.sin(2 * np.pi * f * k * T + phase) - np.sin(phase))])
            for _ in range(per_tick if k < ticks else into):
                m.advance(m.step)
                xs.append(m.position[0])
        at = len(xs) - 1                                                    # [fine steps]
        v = (xs[at] - xs[at - per_tick]) / T                                # [unit/s]
        stop = xs[at] + v * abs(v) / (2 * amax)                             # [unit]
        m.brake()
        for _ in range(20 * per_tick):
            m.advance(m.step)
            xs.append(m.position[0])
        x = np.array(xs)
        measure = np.abs(x[2 * per_tick:] - 2 * x[per_tick:-per_tick] + x[:-2 * per_tick]) / (T * T)
        newest = np.arange(2 * per_tick, len(x))                            # [fine steps]
        assert measure[newest >= at + 2 * per_tick].max() <= amax * (1 + 1e-9), (case, tau)
        before = measure[newest <= at].max()
        assert measure[newest > at].max() <= max(amax, before) * (1 + 1e-9), (case, tau)
        span = config.axes[0].max - config.axes[0].min
        assert (np.sign(v) * (x[at:] - stop)).max() <= 0.01 * span, (case, tau)
        assert abs(x[-1] - stop) <= 1e-12 * span and x[-1] == x[-2], (case, tau)
