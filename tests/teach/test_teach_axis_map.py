"""Map from generalized coordinates to figure axes."""

import math

import numpy as np
import pytest

from marionette.teach.axis_map import AxisMap, Floodlight, Winch, map_axes

SEED = 31337


def _pose(n, **cols):
    q = np.zeros((n, 6))
    for k, name in enumerate(("x0", "y0", "z0", "phi", "theta", "psi")):
        if name in cols:
            q[:, k] = cols[name]
    return q


def test_horizontal_and_rotation_axes():
    t = np.linspace(0, 10, 501)
    psi_true = 1.3 * t - 0.5                          # 2 full turns and more
    q = _pose(t.size, x0=0.3 * np.sin(t), y0=-0.2 * t / 10, psi=np.angle(np.exp(1j * psi_true)))
    out = map_axes(q, AxisMap(rotation_offset=0.25))
    np.testing.assert_allclose(out["x"], q[:, 0])
    np.testing.assert_allclose(out["y"], q[:, 1])
    np.testing.assert_allclose(out["rot"], psi_true + 0.25, atol=1e-12)


def test_winches_vertical_lift_only():
    z = np.linspace(1.2, 1.5, 7)
    cfg = AxisMap(z_ref=1.3, z_gain=0.5)
    out = map_axes(_pose(7, z0=z, psi=np.linspace(0, 3, 7)), cfg)   # yaw has no effect
    for w in cfg.winches:
        np.testing.assert_allclose(out[w.name], 0.5 * (z - 1.3), atol=1e-15)


def test_winch_hand_cases():
    cfg = AxisMap(z_ref=1.3, winches=[Winch("left", (0.0, 0.2, 0.0)), Winch("front", (0.3, 0.0, 0.0)),
                                      Winch("top", (0.0, 0.0, 0.5), gain=-1.0)], lights=[])
    # roll 30 deg lifts the left point by 0.2 sin 30 = 0.1 m
    out = map_axes(_pose(1, z0=1.3, phi=math.radians(30)), cfg)
    assert out["left"][0] == pytest.approx(0.1)
    assert out["front"][0] == pytest.approx(0.0)
    assert out["top"][0] == pytest.approx(-(0.5 * math.cos(math.radians(30)) - 0.5))
    # pitch 30 deg lowers the front point by 0.3 sin 30 = 0.15 m
    out = map_axes(_pose(1, z0=1.3, theta=math.radians(30)), cfg)
    assert out["front"][0] == pytest.approx(-0.15)
    # tilt_gain halves the angle
    cfg.tilt_gain = 0.5
    out = map_axes(_pose(1, z0=1.3, phi=math.radians(60)), cfg)
    assert out["left"][0] == pytest.approx(0.1)


def test_winch_matches_rigid_rotation():
    """dz equals the z change of R p with R = Rz Ry Rx for random poses."""
    from marionette.teach.rucksack import rotation_zyx

    rng = np.random.default_rng(SEED)
    q = np.c_[rng.uniform(-1, 1, (100, 2)), rng.uniform(1.1, 1.5, 100),
              rng.uniform(-0.4, 0.4, (100, 2)), rng.uniform(-3, 3, 100)]
    cfg = AxisMap(z_ref=1.3)
    out = map_axes(q, cfg)
    R = rotation_zyx(q[:, 3], q[:, 4], q[:, 5])
    for w in cfg.winches:
        p = np.array(w.attach)
        expect = (q[:, 2] - 1.3) + (R @ p)[:, 2] - p[2]
        np.testing.assert_allclose(out[w.name], expect, atol=1e-12)


def test_floodlight_hand_case_and_aiming():
    light = Floodlight("pan", "tilt", (0.0, -3.0, 4.0), target_height=1.0)
    cfg = AxisMap(z_ref=1.3, winches=[], lights=[light])
    out = map_axes(_pose(1, z0=1.3), cfg)
    assert out["pan"][0] == pytest.approx(math.pi / 2)     # looking along +y
    assert out["tilt"][0] == pytest.approx(-math.pi / 4)   # 3 m down over 3 m
    rng = np.random.default_rng(SEED + 1)
    q = np.c_[rng.uniform(-0.75, 0.75, (200, 2)), rng.uniform(1.1, 1.5, 200), np.zeros((200, 3))]
    out = map_axes(q, cfg)
    d = np.c_[np.cos(out["tilt"]) * np.cos(out["pan"]), np.cos(out["tilt"]) * np.sin(out["pan"]), np.sin(out["tilt"])]
    target = np.c_[q[:, 0], q[:, 1], 1.0 + q[:, 2] - 1.3] - light.position
    np.testing.assert_allclose(np.cross(d, target), 0, atol=1e-12)
    assert np.all(np.einsum("ij,ij->i", d, target) > 0)


def test_names_are_configuration():
    cfg = AxisMap(x_name="hx", y_name="hy", rotation_name="turn",
                  winches=[Winch("w1", (0, 0, 0.3))], lights=[Floodlight("p", "t", (1, 1, 3))])
    out = map_axes(_pose(3, z0=1.3), cfg)
    assert list(out) == ["hx", "hy", "turn", "w1", "p", "t"] == cfg.axis_names()
    with pytest.raises(ValueError, match=r"duplicated: \['x'\]"):
        AxisMap(winches=[Winch("x", (0, 0, 0))])


def test_dict_round_trip_and_errors():
    cfg = AxisMap(z_gain=0.8, tilt_gain=0.5, rotation_offset=0.1)
    d = cfg.to_dict()
    assert "z_ref" not in d and d["winches"][0]["attach"] == [0.0, 0.0, 0.35]
    assert AxisMap.from_dict(d) == cfg
    cfg2 = AxisMap(z_ref=1.25)
    assert AxisMap.from_dict(cfg2.to_dict()) == cfg2
    with pytest.raises(ValueError, match="unknown axis map key"):
        AxisMap.from_dict({"x_nam": "x"})
    with pytest.raises(ValueError, match="attach must have 3 entries"):
        AxisMap.from_dict({"winches": [{"name": "w", "attach": [0, 1]}]})
    with pytest.raises(ValueError, match="NaN"):
        map_axes(_pose(2, z0=np.nan))
