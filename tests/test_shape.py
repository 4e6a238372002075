"""Offline pragmatic filter (ext/mar_shape.c through marionette._shape, and
marionette.shape): points of rest joined by timed parabolic moves.

Limits are checked on the continuous profile (its parameters and dense
evaluation) to 1e-9 relative, and on the sampled trajectory: a continuous
motion with |a| <= amax has |x[k+1] - 2x[k] + x[k-1]| <= amax*T^2 per step
(the second difference is a hat-weighted mean of the acceleration) and
|x[k+1] - x[k]| <= vmax*T, so those hold too, up to rounding.
"""
import dataclasses
import errno

import numpy as np
import pytest

from marionette import _shape, load_config, load_show
from marionette.demo import DEMO_SHOW
from marionette.errors import ShowError
from marionette.shape import shape_show
from conftest import make_figure, make_show, run_cli

REL = 1e-9
SEED = 20261122


def reach_ref(T, vmax, amax):
    """The feasibility formula [unit], in numpy."""
    T = np.asarray(T, dtype=float)
    return np.where(T >= 2 * vmax / amax, vmax * T - vmax ** 2 / amax, amax * T ** 2 / 4)


def check_profile(p, vmax, amax, n=257):
    """Dense evaluation of a move: ends exact, at rest, limits kept."""
    t = p["t0"] + np.linspace(0, p["duration"], n)
    x, v, a = _shape.evaluate(p, t)
    # t0 + duration - t0 may miss duration by rounding: ends exact to rounding
    assert x[0] == p["x0"] and x[-1] == pytest.approx(p["x1"], rel=1e-12, abs=1e-12)
    assert v[0] == 0 and abs(v[-1]) <= 1e-9 * vmax
    assert p["accel"] <= amax * (1 + REL) and p["peak_speed"] <= vmax * (1 + REL)
    assert np.all(np.abs(v) <= vmax * (1 + REL)) and np.all(np.abs(a) <= amax * (1 + REL))
    lo, hi = min(p["x0"], p["x1"]), max(p["x0"], p["x1"])
    assert np.all((x >= lo) & (x <= hi))
    # the parameters describe the distance covered: the core's, which lasts the
    # duration less half the window at each end at rest, and reaches beyond an
    # open end by the moving average's shift of a parabola; an open end turns
    # over half the window, then ramps between the turn's speed and the cruise's
    d = abs(p["x1"] - p["x0"])
    opens, opene = int(p["open"]) & _shape.OPEN_START, int(p["open"]) & _shape.OPEN_END
    w, V = p["smooth"], p["peak_speed"]
    core = p["duration"] - (0 if opens else w / 2) - (0 if opene else w / 2)
    dc = d + (p["turn"] * bool(opens) + p["turn_end"] * bool(opene)) * w * w / 24
    covered = V * core
    for g, r, accel, ramp in ((p["turn"], w / 2 * bool(opens), p["accel"], p["ramp"]),
                              (p["turn_end"], w / 2 * bool(opene), p["accel_end"], p["ramp_end"])):
        u = g * r                                     # the turn's speed [unit/s]
        assert g <= accel * (1 + REL) and ramp * accel == pytest.approx(V - u, rel=1e-9, abs=1e-12)
        covered -= V * (r + ramp) - (0.5 * u * r + 0.5 * (u + V) * ramp)
    assert covered == pytest.approx(dc, rel=1e-9, abs=1e-15)
    assert p["accel_end"] <= amax * (1 + REL)
    # velocity is the derivative of position
    dx = np.diff(x) / np.diff(t)
    vm = 0.5 * (v[1:] + v[:-1])
    dt = t[1] - t[0]                  # exact for quadratics, off by < a*dt at a corner
    top = max(p["accel"], p["accel_end"])
    assert np.allclose(dx, vm, rtol=1e-6, atol=top * dt + 1e-14 * (1 + np.abs(x).max()) / dt)


def check_sampled(x, T, vmax, amax):
    step = np.abs(np.diff(x))
    assert np.all(step <= vmax * T * (1 + REL) + 1e-12), step.max() / T
    second = np.abs(np.diff(x, 2))
    assert np.all(second <= amax * T * T * (1 + REL) + 1e-12), second.max() / T ** 2


# ---------------------------------------------------------------- one move

def test_hand_computed_moves():
    # 2 s at vmax 2, amax 12: T >= 2*vmax/amax, reach = 2*1 - 4/12 [m]
    assert _shape.reach(1.0, 2.0, 12.0) == pytest.approx(2 - 4 / 12)
    assert _shape.reach(0.2, 2.0, 12.0) == pytest.approx(12 * 0.04 / 4)      # triangle at amax
    assert _shape.min_time(2 - 4 / 12, 2.0, 12.0) == pytest.approx(1.0)
    assert _shape.min_time(0.12, 2.0, 12.0) == pytest.approx(0.2)
    # 1 m in 1 s: triangle, peak speed 2 m/s = vmax, a = 4 m/s^2
    status, p = _shape.plan(0.0, 1.0, 0.0, 1.0, 2.0, 12.0)
    assert status == 0
    assert (p["accel"], p["peak_speed"], p["ramp"]) == pytest.approx((4.0, 2.0, 0.5))
    # 1.5 m in 1 s: the triangle would peak at 3 m/s; cruise at 2 m/s,
    # ramps of 1 - 1.5/2 = 0.25 s at 2/0.25 = 8 m/s^2 (= vmax^2/(vmax*T - D))
    status, p = _shape.plan(0.0, -1.5, 10.0, 1.0, 2.0, 12.0)
    assert status == 0
    assert (p["accel"], p["peak_speed"], p["ramp"]) == pytest.approx((8.0, 2.0, 0.25))
    x, v, a = _shape.evaluate(p, [10.0, 10.25, 10.5, 11.0])
    np.testing.assert_allclose(x, [0.0, -0.25, -0.75, -1.5])
    np.testing.assert_allclose(v, [0.0, -2.0, -2.0, 0.0])
    # beyond reach: infeasible, not an error; nonsense: -EINVAL
    assert _shape.plan(0.0, 1.7, 0.0, 1.0, 2.0, 12.0) == (_shape.INFEASIBLE, None)
    assert _shape.plan(0.0, 1.0, 0.0, 0.0, 2.0, 12.0)[0] == -errno.EINVAL
    assert _shape.plan(0.0, float("nan"), 0.0, 1.0, 2.0, 12.0)[0] == -errno.EINVAL
    assert _shape.plan(0.0, 1.0, 0.0, 1.0, 0.0, 12.0)[0] == -errno.EINVAL


def test_5000_random_moves_keep_the_limits_and_arrive_at_rest():
    rng = np.random.default_rng(SEED)
    n = 5000
    vmax = 10 ** rng.uniform(-2, 1, n)                # [unit/s]
    amax = 10 ** rng.uniform(-1, 2, n)                # [unit/s^2]
    T = 10 ** rng.uniform(-2, 1, n)                   # [s]
    reach = reach_ref(T, vmax, amax)
    D = reach * rng.choice([rng.uniform(0, 1), rng.uniform(0.9, 1.1), 1.0, 0.0], n) \
        * rng.choice([-1, 1], n)
    D = np.where(rng.random(n) < 0.3, reach * rng.uniform(0, 2, n), D)
    counts = {"fit": 0, "infeasible": 0}
    for i in range(n):
        x0 = float(rng.uniform(-1, 1))
        assert _shape.reach(T[i], vmax[i], amax[i]) == pytest.approx(reach[i], rel=1e-12)
        status, p = _shape.plan(x0, x0 + D[i], 0.5, T[i], vmax[i], amax[i])
        d = abs((x0 + D[i]) - x0)
        if d <= reach[i] * (1 + 1e-12):
            assert status == 0, (i, d, reach[i])
            counts["fit"] += 1
            # the least peak acceleration: triangle if its peak speed fits, else cruise at vmax
            if d == 0:
                assert p["accel"] == 0
            elif 2 * d / T[i] <= vmax[i]:
                assert p["accel"] == pytest.approx(min(4 * d / T[i] ** 2, amax[i]), rel=1e-9)
            else:
                want = vmax[i] ** 2 / (vmax[i] * T[i] - d)
                assert p["accel"] == pytest.approx(min(want, amax[i]), rel=1e-9)
                assert p["peak_speed"] == vmax[i]
            if i % 5 == 0:
                check_profile(p, vmax[i], amax[i])
            else:
                assert p["accel"] <= amax[i] * (1 + REL) and p["peak_speed"] <= vmax[i] * (1 + REL)
        else:
            assert status == _shape.INFEASIBLE, (i, d, reach[i])
            counts["infeasible"] += 1
    assert counts["fit"] > 2000 and counts["infeasible"] > 1000, counts


# ---------------------------------------------------------------- points of rest

def test_hysteresis_extrema_by_hand():
    x = np.array([0.0, 1.0, 0.95, 2.0, 1.5, 0.0, 0.3, 0.2, 1.0, 0.9])
    status, e = _shape.extrema(x, 0.5, 0.0)
    assert status == 0
    # 1.0 at tick 1 did not fall by 0.5 before rising again: not a maximum;
    # 0.3 at tick 6 rose only 0.3 after the minimum at tick 5: not a maximum;
    # the last candidate (1.0 at tick 8) is confirmed by the end of the show
    assert e["tick"].tolist() == [0, 3, 5, 8, 9]
    assert e["kind"].tolist() == [0, 1, -1, 1, 0]
    assert e["value"].tolist() == [0.0, 2.0, 0.0, 1.0, 0.9]
    # a flat climax starts at its first tick; its rest runs while within the tolerance
    x = np.array([0.0, 0.5, 1.0, 1.0, 0.99, 0.98, 0.5, 0.0])
    status, e = _shape.extrema(x, 0.3, 0.015)
    assert e["tick"].tolist() == [0, 2, 7] and e["rest_end"].tolist() == [0, 4, 7]
    assert _shape.extrema(np.array([0.0, np.nan]), 0.3, 0.0)[0] == -errno.EINVAL
    assert _shape.extrema(np.array([0.0, 1.0]), 0.0, 0.0)[0] == -errno.EINVAL


def test_prominence_ignores_small_wiggles():
    T = 0.02
    t = np.arange(1000) * T
    slow = 0.4 * np.sin(2 * np.pi * 0.25 * t)                          # extrema every 2 s
    wiggle = 0.01 * np.sin(2 * np.pi * 3.1 * t)                        # [m], < prominence
    status, e = _shape.extrema(slow + wiggle, 0.05, 0.0)
    assert status == 0
    inner = e[e["kind"] != 0]
    assert len(inner) == 10
    expected = (np.arange(10) * 2.0 + 1.0) / T                          # peaks of the sine [tick]
    assert np.all(np.abs(inner["tick"] - expected) <= 8)
    assert np.all(inner["kind"] == np.where(np.arange(10) % 2 == 0, 1, -1))
    # without the prominence every wiggle would count
    assert len(_shape.extrema(slow + wiggle, 1e-6, 0.0)[1]) > 20


# ---------------------------------------------------------------- one axis

def random_trajectory(rng, n, lo, hi):
    k = np.arange(n)
    x = np.zeros(n)
    for _ in range(int(rng.integers(1, 5))):
        x += rng.uniform(0.1, 1.0) * np.sin(2 * np.pi * k / rng.uniform(15, 400) + rng.uniform(0, 6.3))
    if rng.random() < 0.5:                                             # plateaus: points of rest
        x = np.round(x * rng.uniform(1, 4)) / rng.uniform(1, 4)
    x += 0.01 * rng.normal(size=n) * (rng.random() < 0.5)
    x = lo + (x - x.min()) / (np.ptp(x) + 1e-12) * (hi - lo) * rng.uniform(0.3, 1.0)
    return np.clip(x, lo, hi)


@pytest.mark.parametrize("policy", ["reduce", "borrow", "reject"])
def test_random_axes_keep_limits_and_hit_every_climax_on_time(policy):
    rng = np.random.default_rng(SEED + len(policy))
    T = 0.02
    n_infeasible = n_moves = n_borrowed = 0
    for case in range(300):
        n = int(rng.integers(2, 700))
        lo = float(rng.uniform(-1, 0))
        hi = lo + float(rng.uniform(0.2, 2))
        vmax, amax = float(rng.uniform(0.2, 3)), float(rng.uniform(0.5, 20))
        prom = float(rng.uniform(0.01, 0.2)) * (hi - lo)
        tol = float(rng.choice([0.0, rng.uniform(0, 0.5) * prom]))
        x = random_trajectory(rng, n, lo, hi)
        status, out, pts, mv = _shape.shape_axis(x, T, vmax, amax, lo, hi, prom, tol, policy)
        assert status >= 0 and status == np.count_nonzero(mv["shortfall"] > 0), case
        n_infeasible += status
        n_moves += len(mv)
        assert pts["tick"][0] == 0 and pts["tick"][-1] == n - 1 and np.all(np.diff(pts["tick"]) > 0)
        assert len(mv) == len(pts) - 1
        assert np.all((out >= lo) & (out <= hi))
        check_sampled(out, T, vmax, amax)
        start = x[0]
        for i, m in enumerate(mv):
            a, b = pts[i], pts[i + 1]
            assert m["from_tick"] == a["tick"] and m["arrive_tick"] == b["tick"]
            assert a["tick"] <= m["depart_tick"] <= a["rest_end"] < b["tick"] or (
                a["rest_end"] == a["tick"] == m["depart_tick"])
            assert m["x0"] == start
            # the climax: reached exactly at its tick, at rest, held until departure
            assert out[b["tick"]] == m["x1"]
            assert np.all(out[a["tick"]:m["depart_tick"] + 1] == start)
            p = {f: float(m[f]) for f in _shape.PROFILE_FIELDS}
            assert p["t0"] == m["depart_tick"] * T
            assert p["duration"] == pytest.approx((b["tick"] - m["depart_tick"]) * T, rel=1e-12)
            if case % 10 == 0:
                check_profile(p, vmax, amax)
            assert p["accel"] <= amax * (1 + REL) and p["peak_speed"] <= vmax * (1 + REL)
            nominal = reach_ref((b["tick"] - a["rest_end"]) * T, vmax, amax)
            D = abs(b["value"] - start)
            if m["shortfall"] == 0:
                assert m["x1"] == b["value"] and m["action"] == 0         # feasible: exact
                assert D <= nominal * (1 + 1e-12)
            else:
                assert m["shortfall"] == pytest.approx(D - nominal, rel=1e-9, abs=1e-12)
                assert m["action"] != 0
                n_borrowed += bool(m["action"] & _shape.ACT_BORROWED)
                if policy == "borrow":
                    assert m["action"] & _shape.ACT_BORROWED or m["depart_tick"] == a["tick"]
                else:
                    assert m["depart_tick"] == a["rest_end"]
                    assert m["reduced_by"] == pytest.approx(m["shortfall"], rel=1e-9, abs=1e-12)
                if m["action"] & _shape.ACT_REDUCED:
                    # moved toward the start, just enough: the move is now at the limit
                    window = reach_ref(p["duration"], vmax, amax)
                    assert abs(m["x1"] - start) == pytest.approx(window, rel=1e-9, abs=1e-15)
                    assert (m["x1"] - start) * (b["value"] - start) > 0
                else:
                    assert m["x1"] == b["value"]
                assert bool(m["action"] & _shape.ACT_REJECTED) == (policy == "reject")
            start = m["x1"]
    assert n_moves > 2000 and n_infeasible > 50, (n_moves, n_infeasible)
    assert (n_borrowed > 10) == (policy == "borrow"), n_borrowed


def plateau_then_drop(T=0.02):
    """1.0 m held for 40 ticks (a rest), then a drop of 1 m in 0.3 s."""
    x = np.concatenate([np.linspace(0, 1, 60), np.full(40, 1.0), np.linspace(1, 0, 16)[1:],
                        np.zeros(30)])
    return x


def test_borrow_leaves_the_rest_early_instead_of_reducing():
    x = plateau_then_drop()
    T, vmax, amax = 0.02, 2.0, 12.0
    args = (x, T, vmax, amax, -1.0, 2.0, 0.1, 0.001)
    st_r, out_r, pts, mv_r = _shape.shape_axis(*args, "reduce")
    st_b, out_b, _, mv_b = _shape.shape_axis(*args, "borrow")
    assert st_r == st_b == 1
    drop_r, drop_b = mv_r[1], mv_b[1]
    assert (pts["tick"][1], pts["rest_end"][1], pts["tick"][2]) == (59, 99, 114)
    # reduce: keeps the rest, the 15 tick window reaches 12*0.3^2/4 = 0.27 m only
    assert drop_r["depart_tick"] == 99 and drop_r["action"] == _shape.ACT_REDUCED
    assert drop_r["shortfall"] == pytest.approx(1.0 - 0.27)
    assert out_r[114] == pytest.approx(1.0 - 0.27)
    # borrow: min time for 1 m is 1/2 + 2/12 s = 33.3 ticks: leave at 114 - 34 = 80
    assert drop_b["depart_tick"] == 80 and drop_b["action"] == _shape.ACT_BORROWED
    assert drop_b["shortfall"] == drop_r["shortfall"] and drop_b["reduced_by"] == 0
    assert out_b[114] == 0.0 and np.all(out_b[59:81] == 1.0)
    assert out_b[81] < 1.0
    # not before the climax: with a short rest, borrow then reduces
    x2 = np.concatenate([np.linspace(0, 1, 60), np.full(10, 1.0), np.linspace(1, 0, 16)[1:],
                         np.zeros(30)])
    st, out, pts, mv = _shape.shape_axis(x2, T, vmax, amax, -1.0, 2.0, 0.1, 0.001, "borrow")
    m = mv[1]
    assert m["depart_tick"] == pts["tick"][1] == 59
    assert m["action"] == _shape.ACT_BORROWED | _shape.ACT_REDUCED
    window = (pts["tick"][2] - 59) * T
    assert 0 < m["reduced_by"] < m["shortfall"]
    assert 1.0 - out[pts["tick"][2]] == pytest.approx(_shape.reach(window, vmax, amax))


def test_axis_errors():
    x = np.array([0.0, 1.0, 0.0])
    assert _shape.shape_axis(x, 0.02, 2, 12, 0.0, 0.5, 0.1, 0, "reduce")[0] == -errno.ERANGE
    assert _shape.shape_axis(x, 0.0, 2, 12, 0.0, 1.0, 0.1, 0, "reduce")[0] == -errno.EINVAL
    assert _shape.shape_axis(x, 0.02, 2, 12, 0.0, 1.0, 0.1, -1, "reduce")[0] == -errno.EINVAL
    with pytest.raises(ValueError):
        _shape.shape_axis(x, 0.02, 2, 12, 0.0, 1.0, 0.1, 0, "stretch")
    st, out, pts, mv = _shape.shape_axis(np.array([0.3]), 0.02, 2, 12, 0.0, 1.0, 0.1, 0, "reduce")
    assert st == 0 and out.tolist() == [0.3] and len(pts) == 1 and len(mv) == 0


# ---------------------------------------------------------------- shows

def fast_show():
    """A figure whose shows are planned for rate 1 only (follow.rate_max 1), so the
    moves are planned to its bare limits (with lead none)."""
    config = make_figure(2, max_speed=2.0, max_accel=12.0)
    config = dataclasses.replace(config, follow=dataclasses.replace(config.follow, rate_max=1.0))
    slow = 0.5 * np.sin(2 * np.pi * 0.3 * np.arange(400) * 0.02)
    drop = np.concatenate([0.9 * plateau_then_drop(), np.zeros(400 - 145)])
    return config, make_show(config, [slow, drop])


def test_shape_show_reports_and_policies():
    # lead "none": the command is the show itself, so the moves are planned to the full limits
    config, show = fast_show()
    shaped, report = shape_show(show, config, lead="none")
    assert shaped.positions.shape == show.positions.shape
    a1 = report.axis("a1")
    assert report.axis("a0").infeasible == [] and len(a1.infeasible) == 1
    bad = a1.infeasible[0]
    assert (bad.axis, bad.action, bad.borrowed_ticks) == ("a1", "reduced", 0)
    assert bad.time_s == pytest.approx(114 * 0.02) and bad.shortfall == pytest.approx(0.9 - 0.27)
    assert shaped.positions[1, 114] == pytest.approx(0.9 - 0.27)
    text = str(report)
    assert "a1" in text and "1 of" in text and "2.280 s" in text and "short by 0.63" in text
    assert any("shaped (policy reduce, lead none)" in c for c in shaped.changes)
    # borrow: the climax value is kept
    shaped_b, report_b = shape_show(show, config, policy="borrow", lead="none")
    assert report_b.infeasible[0].action == "borrowed" and shaped_b.positions[1, 114] == 0.0
    assert report_b.infeasible[0].borrowed_ticks > 0
    # reject: names the axis, the time and the shortfall
    with pytest.raises(ShowError, match=r"axis 'a1' at 2\.280 s: short by 0\.63"):
        shape_show(show, config, policy="reject", lead="none")
    with pytest.raises(ValueError):
        shape_show(show, config, policy="stretch")
    with pytest.raises(ValueError):
        shape_show(show, config, prominence=0.0)


def test_prominence_and_headroom_options():
    config, show = fast_show()
    _, coarse = shape_show(show, config, prominence=0.95)
    _, fine = shape_show(show, config, prominence={"a0": 0.05})
    assert coarse.axis("a0").extrema < fine.axis("a0").extrema
    _, slow = shape_show(show, config, accel_fraction=0.25)
    a, ax = config.axes[0], slow.axes[0]
    assert ax.plan_accel == pytest.approx(0.25 * ax.headroom * a.max_accel)
    assert ax.plan_speed == pytest.approx(ax.headroom * a.max_speed)
    assert ax.lag == a.time_constant and ax.peak_accel <= ax.plan_accel * (1 + REL)
    with pytest.raises(ValueError, match="lead"):
        shape_show(show, config, lead="ahead")


def test_demo_show_on_the_bundled_figure_keeps_every_limit():
    config = load_config()
    show = load_show(DEMO_SHOW, config)
    for policy in ("reduce", "borrow"):
        shaped, report = shape_show(show, config, policy=policy)
        for j, a in enumerate(config.axes):
            x = shaped.positions[j]
            assert np.all((x >= a.min) & (x <= a.max))
            check_sampled(x, config.tick_period, a.max_speed, a.max_accel)
            pts = report.axes[j].points
            moves = report.axes[j].moves
            np.testing.assert_array_equal(x[pts["tick"][1:]], moves["x1"])
            assert np.all(moves["accel"] <= a.max_accel * (1 + REL))


def test_cli_shape(tmp_path):
    config, show = fast_show()
    figure = tmp_path / "fig.toml"
    lines = ['[figure]', 'name = "t"', 'tick_period = 0.02']
    for a in config.axes:
        lines += ["[[axis]]"] + [f"{k} = {v!r}" if not isinstance(v, str) else f'{k} = "{v}"'
                                 for k, v in a.__dict__.items() if v is not None]
    figure.write_text("\n".join(lines) + "\n")
    src = tmp_path / "taught.csv"
    show.save(src)
    out = tmp_path / "shaped.npz"
    run = run_cli("shape", src, "-o", out, "--config", figure, "--policy", "borrow",
                  "--prominence", "0.05")
    assert run.returncode == 0, run.stderr
    assert "policy borrow" in run.stdout and "left" in run.stdout and out.exists()
    shaped = load_show(out, config)
    assert shaped.positions[1, 114] == 0.0
    run = run_cli("shape", src, "-o", tmp_path / "no.csv", "--config", figure, "--policy", "reject")
    assert run.returncode == 2
    assert "axis 'a1' at 2.280 s: short by" in run.stderr and not (tmp_path / "no.csv").exists()
