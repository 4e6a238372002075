"""Shaping for the engine's command: a shaped show plays through the engine
with its hard limiter idle, the climaxes reach the simulated servos on time,
and play's summary names where the limits did act."""
import dataclasses

import numpy as np
import pytest

from marionette import _shape, load_config, load_show
from marionette.bench import climax
from marionette.demo import DEMO_SHOW
from marionette.engine import Engine
from marionette.limiter_report import WARN_AXIS_TICKS, limited_axes, summary
from marionette.shape import command_model, shape_show
from marionette.show import Show
from conftest import run_cli
from test_shape import check_profile

SEED = 20261202
REL = 1e-9


def test_lag_moves_keep_the_commands_limits_and_end_at_rest():
    """Dense evaluation of random moves: the command x + lag*x' keeps
    |speed| <= vmax and |accel| <= amax; the move itself ends at rest with no
    acceleration, and reach_lag never exceeds the bare reach."""
    rng = np.random.default_rng(SEED)
    fitted = 0
    for _ in range(400):
        vmax, amax = 10 ** rng.uniform(-1, 0.5), 10 ** rng.uniform(0, 1.3)
        lag, T = rng.uniform(0.01, 0.3), rng.uniform(0.1, 3.0)
        reach, w = _shape.reach_lag(T, vmax, amax, lag)
        assert 0 < w < T and 0 < reach <= _shape.reach(T, vmax, amax)
        D = reach * rng.uniform(0.05, 1.3) * rng.choice([-1, 1])
        status, p = _shape.plan(0.3, 0.3 + D, 1.0, T, vmax, amax, lag)
        if abs(D) > reach * (1 + 1e-12):
            assert status == _shape.INFEASIBLE
            continue
        assert status == 0 and 0 < p["smooth"] < T
        fitted += 1
        t = 1.0 + np.linspace(-0.1, T + 0.1, 4001)
        x, v, a = _shape.evaluate(p, t)
        dt = t[1] - t[0]
        assert x[0] == 0.3 and x[-1] == 0.3 + D and v[0] == v[-1] == 0 and a[0] == a[-1] == 0
        # the derivatives are those of the position
        assert np.allclose(np.gradient(x, dt)[1:-1], v[1:-1], atol=2 * abs(a).max() * dt + 1e-12)
        command_speed = v + lag * a
        command_accel = np.gradient(command_speed, dt)
        assert np.all(np.abs(command_speed) <= vmax * (1 + REL))
        # a corner of the acceleration is a jerk step: np.gradient averages over it
        assert np.all(np.abs(command_accel) <= amax * (1 + 1e-6)), abs(command_accel).max() / amax
    assert fitted > 150


@pytest.mark.parametrize("lead", ["dead_time_lag", "mean_delay", "none"])
def test_shaped_random_shows_leave_the_limiter_idle(lead):
    """Many random dances (faster than the servos), shaped for the lead they
    are played with: the engine limits no axis on any tick."""
    config = load_config()
    for seed in range(SEED, SEED + (12 if lead == "dead_time_lag" else 4)):
        taught = climax.random_dance(config, 8.0, seed)
        shaped, report = shape_show(taught, config, lead=lead,
                                    rest_tolerance=0.0 if seed % 2 else None)
        assert report.limited == [], (seed, [a.describe() for a in report.limited])
        with Engine(config, shaped, lead=lead, record=True) as engine:
            engine.step(shaped.n_ticks)
            records = engine.records()
        assert engine.stats()["limited"] == 0 and not np.any(records["excess"]), seed
        # and the unshaped dance does make the limiter act: the check can fail
        with Engine(config, taught, lead=lead, record=True) as engine:
            engine.step(taught.n_ticks)
            assert engine.stats()["limited"] > 0


def test_turns_share_their_acceleration_and_keep_the_commands_limits():
    """300 random axes shaped for a lag, evaluated densely move by move: where two
    moves turn at a climax they meet with velocity 0 and one acceleration, not 0
    (most climaxes without a rest turn so); the command x + lag*x' keeps vmax and
    amax everywhere, across the turns too."""
    rng = np.random.default_rng(SEED)
    turns = flat = 0
    for case in range(300):
        T, n = 0.02, int(rng.integers(100, 600))
        vmax, amax, lag = rng.uniform(0.3, 3.0), rng.uniform(1.0, 20.0), rng.uniform(0.02, 0.25)
        k = np.arange(n)
        x = sum(rng.uniform(0.1, 1.0) * np.sin(2 * np.pi * k / rng.uniform(20, 300) + rng.uniform(0, 6.3))
                for _ in range(3))
        st, out, pts, mv = _shape.shape_axis(x, T, vmax, amax, -5.0, 5.0, 0.05 * np.ptp(x), 0.0,
                                             "reduce", lag, 0.0, 0)
        assert st >= 0
        for a, b in zip(mv[:-1], mv[1:]):
            if a["arrive_tick"] != b["depart_tick"] or (a["x1"] - a["x0"]) * (b["x1"] - b["x0"]) >= 0:
                continue
            t, eps = b["t0"], 1e-7                  # the climax, and just before and after [s]
            xa, va, aa = _shape.evaluate(a, [t - eps])
            xb, vb, ab = _shape.evaluate(b, [t + eps])
            if a["open"] & _shape.OPEN_END:
                assert b["open"] & _shape.OPEN_START
                assert abs(va[0]) <= 2 * eps * abs(aa[0]) and abs(vb[0]) <= 2 * eps * abs(ab[0])
                # one acceleration at the vertex; its rate of change (jerk) is bounded
                assert a["turn_end"] == b["turn"] > 0
                jerk = amax / min(a["smooth"], b["smooth"])     # [unit/s^3]
                assert abs(aa[0] - ab[0]) <= 2 * eps * jerk and aa[0] != 0
                assert np.sign(aa[0]) == -np.sign(a["x1"] - a["x0"])
                assert xa[0] == pytest.approx(a["x1"], abs=eps ** 2 * abs(aa[0]) + 1e-12)
                turns += 1
                if turns % 10 == 0:
                    check_profile(a, vmax, amax)
            else:
                assert not b["open"] & _shape.OPEN_START
                flat += 1
        # the command, densely, over the whole axis
        t = np.linspace(0.0, (n - 1) * T, 40 * n)
        pos, vel, acc = np.full(t.size, x[0]), np.zeros(t.size), np.zeros(t.size)
        for m in mv:
            inside = (t >= m["t0"]) & (t <= m["t0"] + m["duration"])
            pos[inside], vel[inside], acc[inside] = _shape.evaluate(m, t[inside])
        speed = vel + lag * acc
        dt = t[1] - t[0]
        assert np.all(np.abs(speed) <= vmax * (1 + 1e-9)), (case, np.abs(speed).max() / vmax)
        # a corner of the acceleration is a step of the jerk: np.gradient averages over it
        accel = np.gradient(speed, dt)[1:-1]
        assert np.all(np.abs(accel) <= amax * (1 + 1e-6)), (case, np.abs(accel).max() / amax)
    assert flat == 0 and turns > 1000, (turns, flat)


def test_shaped_shows_leave_the_limiter_idle_at_every_rate_the_follower_allows():
    """Random dances shaped for the figure's follow.rate_max (1.1): played at 0.94,
    1.06 and 1.1 the limits never act; shaped for rate 1 only, at 1.1 they do."""
    config = load_config()
    rate1 = dataclasses.replace(config, follow=dataclasses.replace(config.follow, rate_max=1.0))
    for seed in range(SEED, SEED + 4):
        taught = climax.random_dance(config, 8.0, seed)
        shaped, report = shape_show(taught, config)
        assert report.rate_max == 1.1 and "at rates up to 1.1" in str(report)
        for rate in (0.94, 1.06, 1.1):
            assert limited_at(shaped, config, rate) == 0, (seed, rate)
        assert limited_at(shape_show(taught, rate1)[0], config, 1.1) > 0, seed


def limited_at(show, config, rate):
    with Engine(config, show, record=True) as engine:
        engine.set_rate(rate)
        engine.step(int(np.ceil(show.n_ticks / rate)))
        return int(np.count_nonzero(engine.records()["excess"]))


def test_climaxes_land_within_a_tick_on_the_simulated_servos():
    """bench climax on several seeds: the servo's motion around every climax
    within one tick of the show's, with compensation; far off without."""
    for seed in (1, 2, 3):
        r = climax.climax_timing(seed=seed, seconds=10.0)
        assert r["climaxes"] > 40 and r["climax_unmatched_compensated"] < r["climaxes"] / 10
        assert r["limited_axis_ticks_compensated"] == 0
        assert r["climax_error_ticks_max_compensated"] <= climax.TARGET_TICKS, (seed, r)
        assert r["climax_error_ticks_median_uncompensated"] > 2.0


def fast_slow_dance(config, rng, seconds):
    """Per axis, climaxes that turn every time, joined by raised cosines that
    are fast (0.4-0.8 s, often beyond the servo: reduced) and slow (2.5-5 s)
    in turn: every climax lies between a fast move and a slow one."""
    T = config.tick_period
    t = np.arange(int(round(seconds / T))) * T                        # [s]
    positions = np.empty((len(config.axes), t.size))
    for j, a in enumerate(config.axes):
        span, mid = a.max - a.min, 0.5 * (a.min + a.max)              # [unit]
        times, values, up = [0.0, 0.5], [mid, mid], bool(rng.integers(2))
        fast = bool(rng.integers(2))
        while times[-1] < seconds:
            times.append(times[-1] + (rng.uniform(0.4, 0.8) if fast else rng.uniform(2.5, 5.0)))
            room = mid + 0.4 * span - values[-1] if up else values[-1] - (mid - 0.4 * span)
            values.append(values[-1] + (1 if up else -1) * rng.uniform(0.1 * span, room))
            up, fast = not up, not fast
        k = np.searchsorted(times, t, side="right") - 1
        t0, t1 = np.asarray(times)[k], np.asarray(times)[k + 1]
        v0, v1 = np.asarray(values)[k], np.asarray(values)[k + 1]
        positions[j] = v0 + (v1 - v0) * 0.5 * (1 - np.cos(np.pi * (t - t0) / (t1 - t0)))
    return Show(axis_names=config.axis_names, units=[a.unit for a in config.axes],
                positions=positions, loudness=np.zeros(t.size), tick_period=T,
                source="fast_slow_dance")


def test_a_climax_between_a_fast_move_and_a_slow_one_turns_on_time():
    """Random dances (fixed seed) whose every climax joins a fast move and a
    slow one: each climax is a turn (a parabola's vertex, not a flat top) and
    the simulated servo's extremum lies within a tick of it, the limiter idle.
    (Planned to rest there, most such climaxes stayed flat, their extrema up to
    4 ticks off.)"""
    config = load_config()
    rng = np.random.default_rng(SEED)
    errors = []
    for _ in range(3):
        timing, report = climax.servo_timing(config, fast_slow_dance(config, rng, 16.0),
                                             "dead_time_lag")
        assert timing["limited"] == 0 and report.limited == []     # at rate 1 and rate_max
        assert np.all(timing["turning"]), np.count_nonzero(~timing["turning"])
        errors.append(timing["extremum"])
    errors = np.abs(np.concatenate(errors))
    assert errors.size > 200 and not np.any(np.isnan(errors))
    assert errors.max() <= climax.TARGET_TICKS, errors.max()


def test_infeasible_moves_are_reported_with_axis_time_and_trade():
    """A climax too far for its window: reduced (amplitude) or borrowed (time)."""
    config = load_config()
    taught = climax.random_dance(config, 8.0, SEED)
    _, reduced = shape_show(taught, config, policy="reduce")
    _, borrowed = shape_show(taught, config, policy="borrow")
    assert reduced.infeasible and borrowed.infeasible
    seg = reduced.infeasible[0]
    assert seg.action == "reduced" and seg.reduced_by > 0 and seg.axis in config.axis_names
    assert f"axis {seg.axis!r} at {seg.time_s:.3f} s" in str(reduced)
    assert any(s.action.startswith("borrowed") and s.borrowed_ticks > 0 for s in borrowed.infeasible)
    assert "the engine's limits act on 0 axis-ticks" in str(reduced)


def test_first_move_waits_for_the_command_sampled_ahead():
    config = load_config()
    x = config.axes[10]                 # 'x': dead time 0.08 s = 4 ticks ahead
    assert command_model(x, "dead_time_lag", 0.02) == (x.time_constant, x.dead_time, 6)
    assert command_model(x, "none", 0.02) == (0.0, 0.0, 0)


# ---------------------------------------------------------------- the summary

def test_summary_names_axis_time_and_excess():
    """Records with known excesses: the lines name each axis, its runs in
    show time and its largest excess; a warning above WARN_AXIS_TICKS."""
    config = load_config()
    n, T = 200, config.tick_period
    engine = Engine(config, load_show(DEMO_SHOW, config), record=True)
    rec = np.zeros(n, dtype=engine._core.record_dtype)
    engine.close()
    rec["position"] = np.arange(n)
    rec["excess"][50:60, 10] = np.linspace(0.001, 0.01, 10)        # x: 1.00-1.18 s
    rec["excess"][150:152, 10] = -0.02                              # x again: 3.00-3.02 s
    rec["excess"][100, 3] = 0.005                                  # winch_hand_l: 2.00 s
    found = limited_axes(rec, config.axis_names, [a.unit for a in config.axes], T)
    assert [a.axis for a in found] == ["x", "winch_hand_l"]
    x = found[0]
    assert (x.ticks, x.runs, x.max_excess) == (12, 2, 0.02)
    assert x.spans[0] == pytest.approx((1.0, 1.18)) and x.max_excess_s == pytest.approx(3.0)
    lines, warning = summary(rec, config, T)
    text = "\n".join(lines)
    assert "limits acted on 13 axis-ticks, on 2 axes" in text
    assert "x: 12 ticks in 2 run(s) (1.00-1.18 s, 3.00-3.02 s); largest excess 0.02 m at 3.00 s" in text
    assert "winch_hand_l: 1 ticks in 1 run(s) (2.00 s)" in text
    assert warning is not None and "13 axis-ticks" in warning and "x" in warning
    rec["excess"][:] = 0
    rec["excess"][7, 0] = 0.001
    assert WARN_AXIS_TICKS >= 1 and summary(rec, config, T)[1] is None


def test_play_names_the_limited_axes_and_warns(tmp_path):
    """The bundled demo played as it is: the limits act (play says where, and
    warns); shaped: they do not (no warning)."""
    run = run_cli("play")
    assert run.returncode == 0, run.stderr
    assert "largest excess" in run.stdout and "warning: the limits cut the commands" in run.stderr
    shaped = tmp_path / "shaped.npz"
    assert run_cli("shape", DEMO_SHOW, "-o", shaped).returncode == 0
    run = run_cli("play", shaped)
    assert run.returncode == 0, run.stderr
    assert "limits acted on 0 axis-ticks" in run.stdout and "warning" not in run.stderr
