"""Camera calibration (eq. 4.8-4.9): recovery, uncertainty, solvers, refusal of bad sets."""

import dataclasses
import math

import numpy as np
import pytest

from marionette.teach.calibration import calibrate, calibrate_lm, calibrate_steepest_descent
from marionette.teach.camera import IDEAL_PARAMETER_NAMES, CameraParams, look_at, project
from marionette.teach.synthetic import synthetic_markers

SEED = 777


def random_camera(rng):
    """A camera 2-3.5 m high, 4-6 m in front of the 4 m x 4 m area, aimed at its centre."""
    pos = rng.uniform([-6, -6, 2], [6, -4, 3.5])
    target = rng.uniform([-0.5, -0.5, 0.8], [0.5, 0.5, 1.5])
    return look_at(pos, target, roll=rng.uniform(-0.05, 0.05), L=rng.uniform(350, 500))


def rough_guess(rng, cam, pos=0.5, ang=0.08, rel_L=0.15):
    """Starting guess: position within 0.5 m, angles within 0.08 rad, L within 15 %."""
    d = rng.uniform(-1, 1, 7)
    return dataclasses.replace(
        cam, a=cam.a + pos * d[0], b=cam.b + pos * d[1], c=cam.c + pos * d[2],
        alpha=cam.alpha + ang * d[3], beta=cam.beta + ang * d[4], gamma=cam.gamma + ang * d[5],
        L=cam.L * (1 + rel_L * d[6]))


@pytest.mark.parametrize("residual", ["algebraic", "pixel"])
def test_lm_recovers_camera_exactly_from_noise_free_markers(residual):
    rng = np.random.default_rng(SEED)
    for k in range(12):
        cam = random_camera(rng)
        X, pix = synthetic_markers(SEED + k, cam, n=6, noise_px=0.0)
        res = calibrate_lm(X, pix, rough_guess(rng, cam), residual=residual)
        assert res.converged
        np.testing.assert_allclose(res.params.to_vector()[:7], cam.to_vector()[:7], rtol=0, atol=1e-6)
        assert res.rms_px < 1e-6


def test_lm_noisy_markers_within_stated_tolerance():
    """20 markers, 0.5 px noise: position within 0.2 m, angles within 0.5 deg, L within 4 %,
    rms pixel residual 0.3-0.7 px (measured max over 40 cases: 0.16 m, 0.31 deg, 2.8 %)."""
    rng = np.random.default_rng(SEED + 1)
    for k in range(40):
        cam = random_camera(rng)
        X, pix = synthetic_markers(SEED + 100 + k, cam, n=20, noise_px=0.5)
        res = calibrate_lm(X, pix, rough_guess(rng, cam))
        err = res.params.to_vector()[:7] - cam.to_vector()[:7]
        assert np.all(np.abs(err[:3]) < 0.2), err
        assert np.all(np.abs(np.degrees(err[3:6])) < 0.5), err
        assert abs(err[6]) / cam.L < 0.04
        assert 0.3 < res.rms_px < 0.7
        assert res.iterations < 20


def test_standard_uncertainty_matches_actual_scatter():
    """Errors divided by the reported standard uncertainty behave like Student-t with
    2n - 7 = 5 degrees of freedom: median |z| = 0.73 (0.69, 0.70 measured) over
    60 cameras x 7 parameters.  Only 6 markers, so that a wrong residual-variance
    divisor (2n instead of 2n - 7) would move the median to ~1.08."""
    rng = np.random.default_rng(SEED + 2)
    z = []
    for k in range(60):
        cam = random_camera(rng)
        X, pix = synthetic_markers(SEED + 200 + k, cam, n=6, noise_px=0.5)
        res = calibrate_lm(X, pix, rough_guess(rng, cam))
        sigma = np.array([res.uncertainty[n] for n in IDEAL_PARAMETER_NAMES])
        z.append((res.params.to_vector()[:7] - cam.to_vector()[:7]) / sigma)
        assert res.covariance.shape == (7, 7)
        np.testing.assert_allclose(np.sqrt(np.diag(res.covariance)), sigma)
    median = np.median(np.abs(z))
    assert 0.6 < median < 0.88, median


def test_lm_needs_far_fewer_iterations_than_steepest_descent():
    rng = np.random.default_rng(SEED + 3)
    cam = random_camera(rng)
    X, pix = synthetic_markers(SEED + 300, cam, n=8, noise_px=0.5)
    guess = rough_guess(rng, cam)
    lm = calibrate_lm(X, pix, guess, gtol=1e-4)
    sd = calibrate_steepest_descent(X, pix, guess, gtol=1e-4)
    assert lm.converged and sd.converged
    assert lm.iterations * 50 < sd.iterations, (lm.iterations, sd.iterations)
    # both reach the same minimum of F
    assert sd.F == pytest.approx(lm.F, rel=1e-4)
    sigma = np.array([lm.uncertainty[n] for n in IDEAL_PARAMETER_NAMES])
    assert np.all(np.abs(sd.params.to_vector()[:7] - lm.params.to_vector()[:7]) < 0.05 * sigma)
    assert calibrate(X, pix, guess, method="lm").iterations == calibrate_lm(X, pix, guess).iterations


def test_steepest_descent_with_explicit_scaling():
    """User scaling [m, m, m, rad, rad, rad, pixel] reaches the LM minimum of F."""
    rng = np.random.default_rng(SEED + 4)
    cam = random_camera(rng)
    X, pix = synthetic_markers(SEED + 400, cam, n=8, noise_px=0.3)
    guess = rough_guess(rng, cam, pos=0.2, ang=0.03, rel_L=0.05)
    lm = calibrate_lm(X, pix, guess)
    res = calibrate_steepest_descent(X, pix, guess, scale=[1, 1, 1, 0.1, 0.1, 0.1, 100], gtol=1e-3)
    assert res.converged
    assert res.F == pytest.approx(lm.F, rel=1e-3)
    with pytest.raises(ValueError, match="scale must be 7 positive numbers"):
        calibrate_steepest_descent(X, pix, guess, scale=[1, 1, 1])


def test_improved_model_parameters_are_identified():
    """40 markers, 0.1 px noise: delta, epsilon within 3 sigma, q5 within 3 sigma and
    0.003; fitting the ideal model to the same data leaves > 0.3 px rms."""
    rng = np.random.default_rng(SEED + 5)
    for k in range(4):
        cam = random_camera(rng)
        true = dataclasses.replace(cam, delta=rng.uniform(-0.02, 0.02), epsilon=rng.uniform(-0.02, 0.02),
                                   q5=rng.choice([-1, 1]) * rng.uniform(0.01, 0.03),
                                   rho_max=256 * math.sqrt(2) / cam.L)
        X, pix = synthetic_markers(SEED + 500 + k, true, n=40, noise_px=0.1,
                                   low=(-2.5, -2.5, 0.0), high=(2.5, 2.5, 3.0))
        guess = rough_guess(rng, true)
        guess = dataclasses.replace(guess, delta=0.0, epsilon=0.0, q5=0.0)
        full = calibrate_lm(X, pix, guess, free=IDEAL_PARAMETER_NAMES + ("delta", "epsilon", "q5"))
        for name in ("delta", "epsilon", "q5"):
            assert abs(getattr(full.params, name) - getattr(true, name)) < 3 * full.uncertainty[name], name
        assert abs(full.params.q5 - true.q5) < 0.003
        assert full.rms_px < 0.13
        ideal = calibrate_lm(X, pix, guess)
        assert ideal.rms_px > 0.3


def test_coplanar_floor_markers_are_accepted():
    """Markers on the floor (oblique plane) still identify the 7 ideal parameters."""
    rng = np.random.default_rng(SEED + 6)
    cam = look_at((-5, -4, 3), (0, 0, 0.5), L=420)
    X = np.c_[rng.uniform(-2, 2, (10, 2)), np.zeros(10)]
    pix = project(cam, X)
    res = calibrate_lm(X, pix, rough_guess(rng, cam))
    np.testing.assert_allclose(res.params.to_vector()[:7], cam.to_vector()[:7], atol=1e-6)


# ---------------------------------------------------------------------------------
# Refused marker sets
# ---------------------------------------------------------------------------------
def _camera_and_markers(n=8, seed=SEED + 7):
    cam = look_at((-5, -4, 3), (0, 0, 1.2), L=420)
    X, pix = synthetic_markers(seed, cam, n=n, noise_px=0.3)
    return cam, X, pix


def test_too_few_markers():
    cam, X, pix = _camera_and_markers()
    with pytest.raises(ValueError, match="at least 5 markers, got 4"):
        calibrate_lm(X[:4], pix[:4], cam)


def test_collinear_markers_are_named():
    cam = look_at((-5, -4, 3), (0, 0, 1.2), L=420)
    X = np.array([0.1, 0.2, 1.0]) + np.outer(np.linspace(-1, 1, 6), [1.0, 0.5, 0.2])
    labels = [f"M{i}" for i in range(6)]
    with pytest.raises(ValueError, match="markers M0, M1, M2, M3, M4, M5 are collinear"):
        calibrate_lm(X, project(cam, X), cam, labels=labels)


def test_fronto_parallel_plane_is_ill_conditioned():
    """Markers on a plane parallel to the pixel plane: L and the distance trade off."""
    rng = np.random.default_rng(SEED + 8)
    cam = CameraParams(a=0.3, b=-6.0, c=1.5, L=420)
    X = np.c_[rng.uniform(-2, 2, 8), np.zeros(8), rng.uniform(0.2, 2.5, 8)]
    pix = project(cam, X) + rng.normal(0, 0.3, (8, 2))
    guess = CameraParams(a=0.5, b=-5.5, c=1.4, alpha=0.02, gamma=0.03, L=400)
    with pytest.raises(ValueError, match=r"ill-conditioned.*'L'.*'b'|ill-conditioned.*'b'.*'L'") as info:
        calibrate_lm(X, pix, guess)
    assert "coplanar" in str(info.value)


def test_duplicate_markers_are_named():
    cam, X, pix = _camera_and_markers()
    X[5] = X[2] + 1e-4
    with pytest.raises(ValueError, match="markers 2 and 5 coincide"):
        calibrate_lm(X, pix, cam)


def test_markers_behind_guess_are_named():
    cam, X, pix = _camera_and_markers()
    guess = dataclasses.replace(cam, gamma=cam.gamma + math.pi)
    with pytest.raises(ValueError, match=r"markers 0, 1, .* behind the camera at the starting guess"):
        calibrate_lm(X, pix, guess)


def test_not_enough_equations_for_free_parameters():
    cam, X, pix = _camera_and_markers()
    free = IDEAL_PARAMETER_NAMES + ("delta", "epsilon", "q3", "q5")
    with pytest.raises(ValueError, match="10 equations, not enough for 11 free"):
        calibrate_lm(X[:5], pix[:5], cam, free=free)


def test_non_finite_input_is_named():
    cam, X, pix = _camera_and_markers()
    pix[3, 1] = np.nan
    with pytest.raises(ValueError, match="marker 3: pixels"):
        calibrate_lm(X, pix, cam)


def test_guess_is_required():
    cam, X, pix = _camera_and_markers()
    with pytest.raises(TypeError, match="starting guess"):
        calibrate_lm(X, pix, None)
    with pytest.raises(ValueError, match="unknown calibration method"):
        calibrate(X, pix, cam, method="newton")
