"""Camera model: eq. 4.3 (matrix C), eq. 4.2/4.4-4.7 (projection), eq. 4.15-4.23."""

import math

import numpy as np
import pytest

from marionette.teach.camera import (
    ALL_NAMES,
    PARAMETER_NAMES,
    CameraParams,
    camera_coordinates,
    homogeneous_matrix,
    ideal_to_pixel,
    legendre_q3,
    legendre_q5,
    look_at,
    pixel_to_ideal,
    project,
    project_ideal,
    radial_factor,
    rotation_matrix,
)

SEED = 20240601


def _elementary(alpha, beta, gamma):
    """C built independently from the three elementary rotations (yaw, elevation, roll)."""
    ca, sa, cb, sb, cg, sg = (math.cos(alpha), math.sin(alpha), math.cos(beta),
                              math.sin(beta), math.cos(gamma), math.sin(gamma))
    yaw = np.array([[cg, sg, 0], [-sg, cg, 0], [0, 0, 1]])
    elevation = np.array([[1, 0, 0], [0, ca, sa], [0, -sa, ca]])
    roll = np.array([[cb, 0, -sb], [0, 1, 0], [sb, 0, cb]])
    return roll @ elevation @ yaw


def test_rotation_matrix_hand_cases():
    # alpha = 30 deg only: rotation about x, view line tilted up by 30 deg
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    np.testing.assert_allclose(rotation_matrix(math.radians(30), 0, 0),
                               [[1, 0, 0], [0, c, s], [0, -s, c]], atol=1e-15)
    # alpha = beta = gamma = 90 deg, entries of eq. 4.3 by hand: c = 0, s = 1
    np.testing.assert_allclose(rotation_matrix(math.pi / 2, math.pi / 2, math.pi / 2),
                               [[-1, 0, 0], [0, 0, 1], [0, 1, 0]], atol=1e-15)
    # gamma = 90 deg only: view direction (second row) = (-1, 0, 0)
    np.testing.assert_allclose(rotation_matrix(0, 0, math.pi / 2)[1], [-1, 0, 0], atol=1e-15)


def test_rotation_matrix_orthonormal_and_equals_composition():
    rng = np.random.default_rng(SEED)
    angles = rng.uniform(-math.pi, math.pi, (200, 3))
    C = rotation_matrix(angles[:, 0], angles[:, 1], angles[:, 2])
    assert C.shape == (200, 3, 3)
    np.testing.assert_allclose(C @ np.swapaxes(C, 1, 2), np.broadcast_to(np.eye(3), C.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(C), 1.0, atol=1e-14)
    for (a, b, g), Ck in zip(angles, C):
        np.testing.assert_allclose(Ck, _elementary(a, b, g), atol=1e-14)


def test_projection_hand_case_and_pixel_axes():
    cam = CameraParams(a=0, b=0, c=0, L=400.0, R0=255.5, T0=255.5)
    # point 10 m ahead (+y), 1 m to the right (+x), 0.5 m up (+z)
    R, T = project(cam, [1.0, 10.0, 0.5])
    assert R == pytest.approx(255.5 + 400 * 0.1)   # column grows to the right
    assert T == pytest.approx(255.5 + 400 * 0.05)  # row grows upwards


def test_homogeneous_form_is_zero_for_projected_points():
    """A C (x - a) = 0 (eq. 4.7) with A filled from the projection (eq. 4.5)."""
    rng = np.random.default_rng(SEED + 1)
    for _ in range(20):
        cam = look_at(rng.uniform(-6, 6, 3) + [0, -8, 0], rng.uniform(-1, 1, 3),
                      roll=rng.uniform(-0.3, 0.3), L=rng.uniform(300, 900))
        x = rng.uniform(-2, 2, (50, 3))
        ideal = pixel_to_ideal(cam, project(cam, x))
        e = np.einsum("nij,jk,nk->ni", homogeneous_matrix(ideal), cam.rotation, x - cam.position)
        assert np.max(np.abs(e)) < 1e-10


def test_look_at_puts_target_on_optical_axis():
    rng = np.random.default_rng(SEED + 2)
    for _ in range(50):
        pos, tgt = rng.uniform(-5, 5, 3), rng.uniform(-5, 5, 3)
        cam = look_at(pos, tgt, roll=rng.uniform(-1, 1), L=500, R0=300, T0=200)
        np.testing.assert_allclose(project(cam, tgt), [300, 200], atol=1e-9)
        u, v, w = camera_coordinates(cam, tgt)
        assert v == pytest.approx(np.linalg.norm(tgt - pos))


def test_point_behind_camera_is_nan():
    cam = CameraParams(a=0, b=0, c=0)
    assert np.all(np.isnan(project_ideal(cam, [0.0, -1.0, 0.0])))


def test_legendre_values():
    assert legendre_q3(1.0) == 1.0 and legendre_q5(1.0) == 1.0
    assert legendre_q3(0.5) == pytest.approx(-0.4375)          # (5/8 - 3/2)/2
    assert legendre_q5(0.5) == pytest.approx(0.08984375)       # (63/32 - 70/8 + 15/2)/8
    rho = np.linspace(-1, 1, 11)
    np.testing.assert_allclose(legendre_q3(-rho), -legendre_q3(rho))
    # orthogonality on [-1, 1] by Gauss-Legendre quadrature (exact for degree <= 19)
    x, w = np.polynomial.legendre.leggauss(10)
    assert np.sum(w * legendre_q3(x) * legendre_q5(x)) == pytest.approx(0.0, abs=1e-15)
    assert np.sum(w * legendre_q3(x) ** 2) == pytest.approx(2 / 7)
    assert np.sum(w * legendre_q5(x) ** 2) == pytest.approx(2 / 11)


def test_radial_factor_matches_definition_and_is_regular_at_zero():
    rho = np.linspace(0.01, 1.2, 50)
    q3, q5 = 0.03, -0.02
    np.testing.assert_allclose(radial_factor(rho, q3, q5),
                               1 + q3 * legendre_q3(rho) / rho + q5 * legendre_q5(rho) / rho)
    assert radial_factor(0.0, q3, q5) == pytest.approx(1 - 1.5 * q3 + 15 / 8 * q5)


def test_improved_model_hand_case():
    # q3 = q5 = 0: Kp = 1, so r/d = f1 / (1 + f1 eps - h1 delta) (eq. 4.22)
    cam = CameraParams(a=0, b=0, c=0, L=400, R0=250, T0=250, delta=0.02, epsilon=0.01)
    rd, td = pixel_to_ideal(cam, [290.0, 230.0])   # f1 = 0.1, h1 = -0.05
    den = 1 + 0.1 * 0.01 - (-0.05) * 0.02
    assert rd == pytest.approx(0.1 / den) and td == pytest.approx(-0.05 / den)
    # radial only: f2 = f1, rho = |f1| / rho_max, r/d = Kp f1
    cam = CameraParams(a=0, b=0, c=0, L=400, R0=250, T0=250, q5=0.05, rho_max=0.5)
    rd, td = pixel_to_ideal(cam, [350.0, 250.0])   # f1 = 0.25, rho = 0.5
    assert rd == pytest.approx(0.25 * (1 + 0.05 * 0.08984375 / 0.5))
    assert td == pytest.approx(0.0)


def test_ideal_camera_is_eq_4_2():
    rng = np.random.default_rng(SEED + 3)
    cam = CameraParams(a=1, b=2, c=3, L=432.0, R0=250.0, T0=260.0)
    pix = rng.uniform(0, 511, (100, 2))
    np.testing.assert_allclose(pixel_to_ideal(cam, pix), (pix - [250.0, 260.0]) / 432.0)


def test_ideal_to_pixel_inverts_improved_model():
    rng = np.random.default_rng(SEED + 4)
    for _ in range(30):
        cam = CameraParams(a=0, b=0, c=0, L=rng.uniform(300, 600), R0=rng.uniform(240, 270),
                           T0=rng.uniform(240, 270), delta=rng.uniform(-0.03, 0.03),
                           epsilon=rng.uniform(-0.03, 0.03), q3=rng.uniform(-0.03, 0.03),
                           q5=rng.uniform(-0.03, 0.03), rho_max=1.0)
        cam = CameraParams.from_dict({**cam.to_dict(), "rho_max": 256 * math.sqrt(2) / cam.L})
        pix = rng.uniform(0, 511, (200, 2))
        back = ideal_to_pixel(cam, pixel_to_ideal(cam, pix))
        np.testing.assert_allclose(back, pix, atol=1e-8)


def test_project_with_distortion_differs_from_ideal():
    cam = look_at((-5, -4, 3), (0, 0, 1.2), L=420)
    distorted = CameraParams.from_dict({**cam.to_dict(), "q5": 0.03, "delta": 0.01})
    x = np.array([[1.5, 1.0, 1.0]])
    shift = np.abs(project(distorted, x) - project(cam, x)).max()
    assert shift > 0.5   # pixels
    np.testing.assert_allclose(pixel_to_ideal(distorted, project(distorted, x)),
                               project_ideal(cam, x), atol=1e-12)


def test_vector_and_dict_round_trip():
    rng = np.random.default_rng(SEED + 5)
    for _ in range(20):
        values = dict(zip(ALL_NAMES, rng.uniform(0.1, 2.0, len(ALL_NAMES))))
        cam = CameraParams(**values)
        assert CameraParams.from_dict(cam.to_dict()) == cam
        assert all(isinstance(v, float) for v in cam.to_dict().values())
        vec = cam.to_vector()
        assert vec.shape == (len(PARAMETER_NAMES),)
        assert CameraParams.from_vector(vec, base=CameraParams(a=0, b=0, c=0, R0=cam.R0, T0=cam.T0,
                                                               rho_max=cam.rho_max)) == cam
        sub = ("L", "gamma")
        moved = CameraParams.from_vector([123.0, 0.5], sub, base=cam)
        assert moved.L == 123.0 and moved.gamma == 0.5 and moved.a == cam.a


@pytest.mark.parametrize(
    "data, match",
    [
        ({"a": 0, "b": 0, "c": 0, "focal": 3}, "unknown camera parameter"),
        ({"a": 0, "b": 0}, "'c'"),
        ({"a": 0, "b": 0, "c": float("nan")}, "c=nan"),
        ({"a": 0, "b": 0, "c": 0, "L": -5}, "L=-5"),
        ({"a": 0, "b": 0, "c": "x"}, "not a number"),
    ],
)
def test_bad_parameters_are_refused(data, match):
    with pytest.raises(ValueError, match=match):
        CameraParams.from_dict(data)


def test_inverse_refuses_non_monotone_distortion():
    # rho Kp(rho) with q5 = 0.5 decreases near rho = 0.6: no unique inverse beyond
    cam = CameraParams(a=0, b=0, c=0, L=400, R0=0, T0=0, q5=0.5, rho_max=0.5)
    out = ideal_to_pixel(cam, [[0.9, 0.0], [0.01, 0.0]])
    assert np.all(np.isnan(out[0])) and np.all(np.isfinite(out[1]))
