"""Online moves: time-optimal limited profiles, inside the tick."""
import time

import numpy as np
import pytest

from marionette import Engine
from marionette._core import FLAG_HOLDING, FLAG_MOVING, FLAG_STOPPING, plan_move

from conftest import make_figure, make_show, smooth_dance
from test_engine import check_limits


def _random_case(rng):
    vmax, amax = rng.uniform(0.05, 5.0), rng.uniform(0.1, 50.0)
    x0, target = rng.uniform(-2, 2, 2)
    v0 = rng.uniform(-vmax, vmax) if rng.random() < 0.8 else 0.0
    return x0, v0, target, vmax, amax


def test_profiles_respect_limits_end_at_rest_and_are_bang_bang(rng):
    for case in range(5000):
        x0, v0, target, vmax, amax = _random_case(rng)
        duration, ok, _, _ = plan_move(x0, v0, target, vmax, amax)
        assert ok and duration >= 0
        t = np.linspace(0, duration, 400)
        _, _, x, v = plan_move(x0, v0, target, vmax, amax, t)
        assert x[0] == x0 and v[0] == v0
        assert x[-1] == target and v[-1] == 0.0, case
        tol = 1e-9 * (1 + vmax)
        assert np.all(np.abs(v) <= vmax + tol), case
        dt = t[1] - t[0]
        accel = np.diff(v) / dt
        assert np.all(np.abs(accel) <= amax * (1 + 1e-9)), case
        # time-optimal structure: off the phase corners, full acceleration or cruise at top speed
        inner = (np.abs(accel) < amax * (1 - 1e-6))
        corners = np.abs(np.diff(np.sign(np.round(accel / amax, 6)), prepend=0)) > 0
        cruise = inner & ~corners & ~np.roll(corners, -1)
        assert np.all(np.abs(v[1:][cruise]) >= vmax * (1 - 1e-9)), case
        # position is the integral of velocity (no jumps between phases)
        np.testing.assert_allclose(np.diff(x), 0.5 * (v[1:] + v[:-1]) * dt,
                                   atol=1e-9 * (1 + abs(x0) + abs(target)) + amax * dt ** 2)


def test_timed_profiles_last_exactly_as_long_as_asked(rng):
    stretched = 0
    for case in range(3000):
        x0, v0, target, vmax, amax = _random_case(rng)
        best, _, _, _ = plan_move(x0, v0, target, vmax, amax)
        want = best * rng.uniform(1.0, 3.0) + rng.uniform(0, 0.5)
        t = np.linspace(0, want, 300)
        duration, ok, x, v = plan_move(x0, v0, target, vmax, amax, t, duration=want)
        if not ok:                                   # no single-cruise profile: time-optimal instead
            assert duration == pytest.approx(best)
            continue
        stretched += 1
        assert duration == pytest.approx(want, rel=1e-9)
        # t[-1] == want may sit a rounding error before the profile's end
        assert x[-1] == pytest.approx(target, abs=1e-12) and abs(v[-1]) <= 1e-9 * vmax
        assert np.all(np.abs(v) <= vmax * (1 + 1e-9))
        assert np.all(np.abs(np.diff(v)) <= amax * (t[1] - t[0]) * (1 + 1e-9))
        with pytest.raises(AssertionError):
            assert plan_move(x0, v0, target, vmax, amax, duration=best * 0.5)[1]
    assert stretched > 2500


def _run(engine, n):
    engine.step(n)
    return engine.records()


def test_move_to_from_a_moving_figure_reaches_the_pose_at_rest(rng):
    for case in range(30):
        config = make_figure(4, max_speed=rng.uniform(0.2, 2), max_accel=rng.uniform(1, 20))
        show = make_show(config, smooth_dance(config, 400, rng, fraction=0.9))
        pose = {a.name: rng.uniform(a.min, a.max) for a in config.axes}
        sync = bool(case % 2)
        with Engine(config, show, record=True) as engine:
            engine.step(int(rng.integers(5, 200)))        # moving along the show
            engine.move_to(pose, synchronized=sync)
            r = _run(engine, 600)
        check_limits(config, r["command"], show.positions[:, 0])
        target = np.array(list(pose.values()))
        np.testing.assert_array_equal(r["command"][-1], target)
        moving = (r["flags"] & FLAG_MOVING) != 0
        assert moving.any() and r["flags"][-1] & FLAG_HOLDING
        first_move = np.argmax(moving)
        assert np.all(r["position"][first_move:] == r["position"][first_move])  # playback waits
        arrive = [np.argmax(np.all(r["command"][:, j:j + 1] == r["command"][-1, j], axis=1)
                       & (np.arange(len(r)) >= first_move)) for j in range(4)]
        if sync:
            assert max(arrive) - min(arrive) <= 1, arrive


def test_stop_ramp_decelerates_at_the_limit_without_reversing(rng):
    config = make_figure(3, max_speed=1.0, max_accel=4.0)
    t = np.arange(400) * 0.02
    ramp = np.vstack([np.clip(-0.9 + 0.8 * t, -1, 1)] * 3)     # 0.8 m/s, a constant move
    with Engine(config, make_show(config, ramp), lead="none", record=True) as engine:
        engine.step(50)
        engine.stop_motion()
        r = _run(engine, 100)
    v = np.diff(r["command"][:, 0]) / 0.02
    after = v[50:]
    assert np.all(after >= -1e-12)                              # never turns back
    stopped = 50 + np.argmax(after <= 0)
    assert stopped - 50 <= int(np.ceil(0.8 / 4.0 / 0.02)) + 1   # 0.2 s at 4 m/s^2
    assert np.all(r["flags"][-1] & FLAG_HOLDING)
    check_limits(config, r["command"], ramp[:, 0])


def test_stop_ramps_are_not_counted_as_limited():
    """Stop ramps from 18 places of the shaped bundled demo: planned a hair inside
    the limits, the limiter does not count their ticks as cut (rounding at the
    bound counted 104 axis-ticks when they were planned at the limits)."""
    from marionette import load_config, load_show
    from marionette.demo import DEMO_SHOW
    from marionette.shape import shape_show
    config = load_config()
    show, _ = shape_show(load_show(DEMO_SHOW, config), config)
    moving = 0
    for at in range(60, 1000, 52):
        with Engine(config, show, record=True) as engine:
            engine.step(at)
            engine.stop_motion()
            engine.step(100)
            r = engine.records()
        assert not np.any(r["excess"]), at
        assert np.all(r["flags"][-1] & FLAG_HOLDING)
        moving += np.any(np.abs(np.diff(r["command"][at - 2:at + 1], axis=0)) > 1e-6)
    assert moving > 15                          # the ramps start from a moving figure


def test_blend_in_from_home_then_play(rng):
    config = make_figure(3)
    show = make_show(config, smooth_dance(config, 500, rng, fraction=0.8))
    with Engine(config, show, start_pose="home", record=True, lead="none") as engine:
        r = _run(engine, 10)
        assert np.all(r["flags"] & FLAG_HOLDING)
        np.testing.assert_array_equal(r["command"], 0.0)          # home
        engine.blend_in(position=100.0)
        r = _run(engine, 400)
    check_limits(config, r["command"], np.zeros(3))
    playing = (r["flags"] & (FLAG_MOVING | FLAG_HOLDING)) == 0
    first = np.argmax(playing)
    assert playing[first:].all() and first > 10
    np.testing.assert_array_equal(r["position"][first], 100.0)
    np.testing.assert_allclose(r["position"][first:], 100.0 + np.arange(len(r) - first))
    # once playing, the commands are the show itself (lead "none", no limit acting)
    k = np.arange(first + 5, len(r))
    np.testing.assert_allclose(r["command"][k], show.positions[:, r["position"][k].astype(int)].T,
                               atol=1e-12)


def wait_ticks(engine, n, until=lambda snap: False):
    """Waits until the real-time loop has run n more ticks, or until
    until(snapshot) holds; returns the last snapshot. Counted in the loop's
    ticks, not in seconds: on a loaded machine they come later, and the
    moves, timed in ticks, take as many of them."""
    snap = engine.snapshot()
    start = -1 if snap is None else snap.tick
    while snap is None or (snap.tick < start + n and not until(snap)):
        assert engine.running, "the real-time loop stopped"
        time.sleep(0.005)
        snap = engine.snapshot()
    return snap


def test_retarget_and_abort_while_the_loop_runs(rng):
    config = make_figure(3, max_speed=0.5, max_accel=2.0)
    show = make_show(config, smooth_dance(config, 3000, rng))
    home = lambda snap: bool(snap.flags & FLAG_HOLDING) and list(snap.commands.values()) == [0.0, 0.0, 0.0]
    with Engine(config, show, record=True) as engine:
        engine.start(priority=0)
        engine.move_to({"a0": 0.9, "a1": -0.9, "a2": 0.5})
        wait_ticks(engine, 15)                                                  # 0.3 s
        engine.move_to({"a0": -0.8, "a1": 0.8, "a2": -0.5}, synchronized=True)   # retarget
        wait_ticks(engine, 15)
        engine.stop_motion()                                                    # abort
        wait_ticks(engine, 25)
        engine.move_to("home")
        # from anywhere inside the limits (1 m away at most) the move home
        # takes 1 / 0.5 + 0.5 / 2 s = 113 ticks; 500 is plenty
        wait_ticks(engine, 500, home)
        engine.stop()
        r = engine.records()
        overruns = engine.stats()["overruns"]
    assert np.any(r["flags"] & FLAG_STOPPING)
    check_limits(config, r["command"], show.positions[:, 0], stopping=r["flags"] & FLAG_STOPPING)
    # (a GOTO's profile runs a period per tick, so missed deadlines only
    # delay it; run by the elapsed periods, it once ended with the commands
    # short of home: ext/mar_engine.c)
    np.testing.assert_array_equal(r["command"][-1], 0.0, err_msg=f"{overruns} overruns")


def test_bad_poses_are_refused():
    config = make_figure(2)
    with Engine(config, make_show(config, np.zeros((2, 10)))) as engine:
        with pytest.raises(ValueError, match=r"axis 'a1' position 3.0 m is outside"):
            engine.move_to({"a1": 3.0})
        with pytest.raises(ValueError, match="unknown axis 'elbow'"):
            engine.move_to({"elbow": 0.0})
        with pytest.raises(ValueError, match="unknown pose"):
            engine.move_to("somewhere")
    with pytest.raises(ValueError, match="no position for axis 'a1'"):
        Engine(config, make_show(config, np.zeros((2, 10))), start_pose={"a0": 0.0})
