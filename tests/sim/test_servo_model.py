"""The simulated servos' behaviour model: exact where no limit acts, and the
limits hold in random cases."""
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
