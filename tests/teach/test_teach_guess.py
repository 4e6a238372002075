"""Linear starting guess of a camera (DLT for markers in space, homography in a plane)."""
import numpy as np
import pytest

from marionette.teach.camera import IDEAL_PARAMETER_NAMES, CameraParams, look_at, project
from marionette.teach.guess import starting_guess

SEED = 606


def _cameras(rng, n):
    for _ in range(n):
        pos = rng.uniform([-6, -6, 2], [6, -4, 3.5])
        target = rng.uniform([-0.5, -0.5, 0.8], [0.5, 0.5, 1.5])
        yield look_at(pos, target, roll=rng.uniform(-0.05, 0.05), L=rng.uniform(350, 500))


def _error(guess, cam):
    e = guess.to_vector(IDEAL_PARAMETER_NAMES) - cam.to_vector(IDEAL_PARAMETER_NAMES)
    return np.abs(e[:3]).max(), np.degrees(np.abs(e[3:6])).max(), abs(e[6]) / cam.L


@pytest.mark.parametrize("plane", [False, True])
def test_guess_is_exact_without_noise_and_close_with_noise(plane):
    """Noise-free: exact to 1e-6. 12 markers, 0.5 px noise: within 0.4 m, 2 deg and
    10 % (measured over these 2 x 8 cameras up to 0.26 m, 1.5 deg, 6 %), inside what
    calibration needs (about 1 m, 0.2 rad, 50 %)."""
    rng = np.random.default_rng(SEED + plane)
    for cam in _cameras(rng, 8):
        if plane:                                   # on the floor
            X = np.c_[rng.uniform(-2, 2, (12, 2)), np.zeros(12)]
        else:
            X = rng.uniform([-2, -2, 0], [2, 2, 2.5], (12, 3))
        pix = project(cam, X)
        exact = starting_guess(X, pix, cam.R0, cam.T0)
        assert max(_error(exact, cam)) < 1e-6
        noisy = starting_guess(X, pix + rng.normal(0, 0.5, pix.shape), cam.R0, cam.T0)
        pos, ang, rel_L = _error(noisy, cam)
        assert pos < 0.4 and ang < 2.0 and rel_L < 0.10, (pos, ang, rel_L)


def test_rho_max_from_the_image_diagonal():
    cam = look_at((-5, -4, 3), (0, 0, 1.2), L=420)
    X = np.random.default_rng(SEED).uniform([-2, -2, 0], [2, 2, 2.5], (10, 3))
    g = starting_guess(X, project(cam, X), cam.R0, cam.T0, image_diagonal_half=362.0)
    assert g.rho_max == pytest.approx(362.0 / g.L)


def test_refusals():
    cam = look_at((-5, -4, 3), (0, 0, 1.2), L=420)
    X = np.random.default_rng(SEED).uniform([-2, -2, 0], [2, 2, 2.5], (10, 3))
    pix = project(cam, X)
    with pytest.raises(ValueError, match="5 markers not in one plane; an automatic guess needs at least 6"):
        starting_guess(X[:5], pix[:5], cam.R0, cam.T0)
    with pytest.raises(ValueError, match="3 markers"):
        starting_guess(X[:3], pix[:3], cam.R0, cam.T0)
    line = np.outer(np.linspace(-1, 1, 6), [1.0, 0.5, 0.2])
    with pytest.raises(ValueError, match="one line"):
        starting_guess(line, project(cam, line), cam.R0, cam.T0)
    front = CameraParams(a=0.0, b=-6.0, c=1.5, L=420.0)           # looking along +y
    wall = np.c_[np.linspace(-2, 2, 8), np.zeros(8), np.tile([0.3, 2.2], 4)]
    with pytest.raises(ValueError, match="parallel to the image plane"):
        starting_guess(wall, project(front, wall), front.R0, front.T0)
