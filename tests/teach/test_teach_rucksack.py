"""Rucksack generalized coordinates (eq. 5.1-5.7), nonlinear fit, strobe timing."""

import math

import numpy as np
import pytest

from marionette.teach.rucksack import (
    SET_PERIOD,
    align_to_set_times,
    angles_from_rotation,
    fit_linear,
    fit_nonlinear,
    group_sets,
    led_body_coordinates,
    led_positions,
    rotation_zyx,
)

SEED = 5150


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def random_poses(rng, n, max_tilt):
    pose = np.empty((n, 6))
    pose[:, :2] = rng.uniform(-2, 2, (n, 2))
    pose[:, 2] = rng.uniform(1.0, 1.6, n)
    pose[:, 3:5] = rng.uniform(-max_tilt, max_tilt, (n, 2))
    pose[:, 5] = rng.uniform(-np.pi, np.pi, n)
    return pose


def test_led_order_hand_case():
    """Square b = 0.5 at (1, 2, 3), level, yaw 0: eq. 5.3-5.7 by hand."""
    X = np.array([[1.5, 2.5, 3.0], [0.5, 2.5, 3.0], [0.5, 1.5, 3.0], [1.5, 1.5, 3.0]])
    fit = fit_linear(X, 0.5)
    np.testing.assert_allclose(fit.pose, [1, 2, 3, 0, 0, 0], atol=1e-15)
    assert fit.cos_psi == pytest.approx(1.0) and fit.sin_psi == pytest.approx(0.0)
    # lift LEDs 1 and 2 (the +y side) by 0.01 m: phi = (z1 - z4 + z2 - z3)/(4b) = 0.02/2
    Y = X.copy()
    Y[:2, 2] += 0.01
    assert fit_linear(Y, 0.5).pose[3] == pytest.approx(0.01)
    # lower LEDs 1 and 4 (the front, +x) by 0.01 m: theta = (z2 - z1 + z3 - z4)/(4b) = 0.01
    Z = X.copy()
    Z[[0, 3], 2] -= 0.01
    assert fit_linear(Z, 0.5).pose[4] == pytest.approx(0.01)
    # yaw 90 deg: LED1 moves to (-b, +b)
    W = X.copy()
    W[:, :2] = [1, 2] + np.array([[-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5], [0.5, 0.5]])
    assert fit_linear(W, 0.5).pose[5] == pytest.approx(math.pi / 2)
    np.testing.assert_allclose(led_body_coordinates(0.5)[:, :2], [[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5]])


def test_rotation_is_zyx_and_inverts():
    rng = np.random.default_rng(SEED)
    a = rng.uniform(-1.4, 1.4, (300, 3))
    R = rotation_zyx(a[:, 0], a[:, 1], a[:, 2])
    for (phi, theta, psi), Rk in zip(a[:20], R[:20]):
        c, s = math.cos, math.sin
        Rz = np.array([[c(psi), -s(psi), 0], [s(psi), c(psi), 0], [0, 0, 1]])
        Ry = np.array([[c(theta), 0, s(theta)], [0, 1, 0], [-s(theta), 0, c(theta)]])
        Rx = np.array([[1, 0, 0], [0, c(phi), -s(phi)], [0, s(phi), c(phi)]])
        np.testing.assert_allclose(Rk, Rz @ Ry @ Rx, atol=1e-15)
    np.testing.assert_allclose(angles_from_rotation(R), a, atol=1e-12)


def test_analytic_formulas_are_exact_on_the_linearised_model():
    """x_i = x0 + B^T u_i with the linearised B (eq. 5.1) gives q back exactly."""
    rng = np.random.default_rng(SEED + 1)
    b = 0.2
    u = led_body_coordinates(b)
    for pose in random_poses(rng, 200, 0.1):
        phi, theta, psi = pose[3:]
        c, s = math.cos(psi), math.sin(psi)
        Bt = np.array([[c, -s, theta * c + phi * s], [s, c, theta * s - phi * c], [-theta, phi, 1]])
        X = pose[:3] + u @ Bt.T
        fit = fit_linear(X, b)
        np.testing.assert_allclose(fit.pose[:5], pose[:5], atol=1e-12)
        assert fit.cos_psi == pytest.approx(c, abs=1e-12) and fit.sin_psi == pytest.approx(s, abs=1e-12)


def test_linear_fit_on_rigid_square_small_tilts():
    """Exact rigid square, tilts <= 5 deg: position exact, roll/pitch within 0.05 deg,
    yaw within 0.3 deg (the linearisation error is of third/second order)."""
    rng = np.random.default_rng(SEED + 2)
    pose = random_poses(rng, 2000, math.radians(5))
    fit = fit_linear(led_positions(pose, 0.2), 0.2)
    np.testing.assert_allclose(fit.pose[:, :3], pose[:, :3], atol=1e-12)
    assert np.max(np.abs(np.degrees(fit.pose[:, 3:5] - pose[:, 3:5]))) < 0.05
    assert np.max(np.abs(np.degrees(_wrap(fit.pose[:, 5] - pose[:, 5])))) < 0.3


def test_nonlinear_fit_is_exact_for_large_tilts():
    rng = np.random.default_rng(SEED + 3)
    pose = random_poses(rng, 500, math.radians(35))
    X = led_positions(pose, 0.25)
    lin = fit_linear(X, 0.25)
    assert np.max(np.abs(np.degrees(lin.pose[:, 3:5] - pose[:, 3:5]))) > 1.0   # linear is biased
    fit = fit_nonlinear(X, 0.25)
    np.testing.assert_allclose(fit.pose[:, :5], pose[:, :5], atol=1e-9)
    np.testing.assert_allclose(_wrap(fit.pose[:, 5] - pose[:, 5]), 0, atol=1e-9)
    assert np.max(fit.residual_m) < 1e-9


def test_angle_accuracy_under_led_noise():
    """10 mm (per coordinate) LED noise, b = 0.2 m, tilts <= 6 deg: rms angle error
    <= 2.0 deg for roll/pitch/yaw (theory: sigma / (2b) = 1.43 deg for roll and pitch,
    sigma / (2 sqrt(2) b) = 1.0 deg for yaw)."""
    rng = np.random.default_rng(SEED + 4)
    pose = random_poses(rng, 5000, math.radians(6))
    X = led_positions(pose, 0.2) + rng.normal(0, 0.01, (5000, 4, 3))
    for fit in (fit_linear(X, 0.2), fit_nonlinear(X, 0.2)):
        d = fit.pose - pose
        d[:, 5] = _wrap(d[:, 5])
        rms = np.degrees(np.sqrt(np.mean(d[:, 3:] ** 2, axis=0)))
        assert np.all(rms < 2.0), rms
        assert np.all(rms[:2] > 1.0)          # noise does reach the estimate
        assert np.sqrt(np.mean(d[:, :3] ** 2)) < 0.006   # sigma / 2 = 5 mm


def test_missing_led_gives_nan():
    X = led_positions(np.array([[0, 0, 1.3, 0, 0, 0.3]]), 0.2)
    X[0, 2] = np.nan
    assert np.all(np.isnan(fit_linear(X, 0.2).pose)) and np.all(np.isnan(fit_nonlinear(X, 0.2).pose))


def _strobed(pose_of_t, b, n_sets, t0=0.0):
    times = np.round(t0 + 0.02 * np.arange(4 * n_sets), 9)
    leds = np.arange(4 * n_sets) % 4 + 1
    pts = led_positions(pose_of_t(times), b)[np.arange(times.size), leds - 1]
    return times, leds, pts


def test_alignment_removes_strobe_skew():
    """A dancer walking at 1.5 m/s while turning at 1 turn / 2 s: grouping the four
    fields naively is off by up to 60 ms of motion; interpolating each LED to the set
    time is exact for the straight walk and within 3 mm for the turn (chord error of
    linear interpolation over 80 ms on the LED circle, r (1 - cos(w T / 2)) = 2.2 mm)."""
    def pose_of_t(t):
        p = np.zeros((t.size, 6))
        p[:, 0] = -2 + 1.5 * t
        p[:, 2] = 1.3
        p[:, 5] = math.pi * t
        return p
    times, leds, pts = _strobed(pose_of_t, 0.2, 40, t0=0.1)
    tc, sets = align_to_set_times(times, leds, pts)
    np.testing.assert_allclose(tc, 0.1 + 0.03 + SET_PERIOD * np.arange(40))
    truth = led_positions(pose_of_t(tc), 0.2)
    inner = slice(1, -1)          # the first/last set have no neighbour on one side
    assert np.max(np.linalg.norm(sets[inner] - truth[inner], axis=-1)) < 0.003
    # LED3/LED4 (fields +40, +60 ms) of set 0 and LED1/LED2 of the last set lack a neighbour
    assert np.all(np.isnan(sets[0, 2:])) and np.all(np.isfinite(sets[0, :2]))
    assert np.all(np.isnan(sets[-1, :2])) and np.all(np.isfinite(sets[-1, 2:]))
    _, naive = group_sets(times, leds, pts)
    assert np.max(np.linalg.norm(naive[inner] - truth[inner], axis=-1)) > 0.05
    fit = fit_linear(sets[inner], 0.2)
    np.testing.assert_allclose(fit.pose[:, 0], pose_of_t(tc[inner])[:, 0], atol=1e-3)


def _walk_and_turn(t):
    """Walking at 1.5 m/s while turning at 1 turn / 2 s, bobbing 5 cm at 1.5 Hz."""
    p = np.zeros((t.size, 6))
    p[:, 0] = -2 + 1.5 * t
    p[:, 2] = 1.3 + 0.05 * np.sin(2 * math.pi * 1.5 * t)
    p[:, 5] = math.pi * t
    return p


def test_alignment_bridges_one_lost_sample():
    """Every LED loses single samples, one LED of a set at a time, at random: with the
    rucksack's size each loss is bridged by the cubic through two samples either side
    (within 3 mm of the truth on this walk and turn); without it the one or two set
    times around each loss stay NaN. Two losses in a row stay NaN either way."""
    rng = np.random.default_rng(SEED + 7)
    times, leds, pts = _strobed(_walk_and_turn, 0.2, 60)
    lost = np.arange(8, 4 * 60 - 8, 12) + rng.integers(0, 4, 19)   # at most one per set
    pts[lost] = np.nan
    tc, plain = align_to_set_times(times, leds, pts)
    _, sets = align_to_set_times(times, leds, pts, half_side=0.2)
    truth = led_positions(_walk_and_turn(tc), 0.2)
    gap = np.isnan(plain[..., 0])
    gap[:2] = gap[-2:] = False                    # the ends lack a neighbour on one side
    assert gap.sum() >= lost.size                 # each loss opened one or two set times
    assert np.all(np.isfinite(sets[gap]))
    assert np.max(np.linalg.norm(sets[gap] - truth[gap], axis=-1)) < 0.003
    np.testing.assert_array_equal(sets[~gap][2:-2], plain[~gap][2:-2])
    pts[lost + 4] = np.nan                       # the same LED's next sample too
    _, sets = align_to_set_times(times, leds, pts, half_side=0.2)
    assert np.all(np.isnan(sets[(tc > times[lost[0]]) & (tc < times[lost[0] + 4]), leds[lost[0]] - 1]))


def test_bridge_stays_lost_where_the_rucksack_disagrees():
    """A stray sample next to a loss (8 cm off, as a reflection that passed the
    triangulation) moves the cubic across the gap by about 4.5 cm: its distances to the
    LEDs of its set then miss the square by more than the tolerance, and the set time
    stays NaN; without the check the bridge would have been taken."""
    times, leds, pts = _strobed(_walk_and_turn, 0.2, 20)
    k = 4 * 10 + 1                                # LED2 of set 10
    pts[k] = np.nan
    centre = _walk_and_turn(times[k - 4:k - 3])[0, :3]
    outward = (pts[k - 4] - centre) / np.linalg.norm(pts[k - 4] - centre)
    pts[k - 4] += 0.08 * outward                  # the sample before the loss, astray
    tc, sets = align_to_set_times(times, leds, pts, half_side=0.2)
    around = (tc > times[k - 4]) & (tc < times[k + 4])
    assert around.sum() == 2 and np.all(np.isnan(sets[around, 1]))
    _, loose = align_to_set_times(times, leds, pts, half_side=0.2, bridge_tolerance=np.inf)
    assert np.all(np.isfinite(loose[around, 1]))


def test_alignment_leaves_long_gaps_open():
    """LED2 (field +20 ms) lost in sets 4 and 5: set times 3, 4, 5 (at +30 ms) have no
    LED2 pair at most 80 ms apart around them and stay NaN; sets 2 and 6 are fine."""
    times, leds, pts = _strobed(lambda t: np.c_[t, 0 * t, 1.3 + 0 * t, 0 * t, 0 * t, 0 * t], 0.2, 10)
    sel = np.nonzero(leds == 2)[0][4:6]
    pts[sel] = np.nan
    _, sets = align_to_set_times(times, leds, pts)
    assert np.all(np.isnan(sets[3:6, 1]))
    assert np.all(np.isfinite(sets[2, 1])) and np.all(np.isfinite(sets[6, 1]))
    assert np.all(np.isfinite(sets[1:-1][:, [0, 2, 3]]))
    with pytest.raises(ValueError, match="LED number 5"):
        align_to_set_times(times, np.where(leds == 4, 5, leds), pts)
