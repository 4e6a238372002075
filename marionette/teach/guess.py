"""Starting guess of a camera from its markers, without user input.

Calibration (eq. 4.8-4.9) minimises a non-convex function and needs a starting guess.
Here a linear solution provides one, in the frame of :mod:`marionette.teach.camera`:

With the optical axis ``(R0, T0)`` known, the measured image vector
``m = (R - R0, T - T0, 1)`` is proportional to ``K Q (x - a)`` where
``K = diag(L, L, 1)`` and ``Q`` holds the rows ``c1, c3, c2`` of C (``u, w, v``: right,
up, depth).  So ``m ~ P (x, 1)`` with the 3 x 4 matrix ``P = K Q [I | -a]``.

* Markers not in one plane, n >= 6: the direct linear transformation (DLT) solves the
  2n homogeneous equations ``m x (P X) = 0`` for the 12 entries of P (SVD, with
  Hartley's normalisation), then reads ``L``, ``C`` (nearest rotation) and ``a`` off P.
* Markers in one plane, n >= 4: the plane homography ``H = K Q [e1 e2 (mu - a)]``
  (plane coordinates along e1, e2 from the centroid mu) is solved the same way;
  orthogonality and equal length of ``Q e1`` and ``Q e2`` give ``1/L^2`` by least
  squares.  A plane parallel to the image plane leaves L undetermined (refused).

The result is only a starting point (the DLT ignores that P has 7, not 11, degrees of
freedom); :mod:`marionette.teach.calibration` refines it.  Failures raise
``ValueError`` with the reason.
"""

from __future__ import annotations

import math

import numpy as np

from .camera import CameraParams
from marionette.errors import ArgumentError

PLANE_TOLERANCE = 1e-3   # markers within this distance of a plane count as coplanar [m]


def _normalise_image(m: np.ndarray):
    """Scale centred image coordinates (n, 2) [pixel] to rms sqrt(2); returns (scaled, s)."""
    s = float(np.sqrt(np.mean(np.sum(m * m, axis=1)) / 2.0))
    if s == 0.0:
        raise ArgumentError("all markers are imaged on the optical axis")
    return m / s, s


def _null_vector(A: np.ndarray) -> np.ndarray:
    _, _, vt = np.linalg.svd(A)
    return vt[-1]


def _angles(C: np.ndarray) -> tuple[float, float, float]:
    """(alpha, beta, gamma) [rad] of a rotation matrix C of eq. 4.3."""
    alpha = math.asin(max(-1.0, min(1.0, C[1, 2])))
    gamma = math.atan2(-C[1, 0], C[1, 1])
    beta = math.atan2(-C[0, 2], C[2, 2])
    return alpha, beta, gamma


def _nearest_rotation(M: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(M)
    R = U @ Vt
    if np.linalg.det(R) < 0:
        U[:, -1] *= -1.0
        R = U @ Vt
    return R


def _camera(C, a, L, R0, T0, rho_max, image_diagonal_half):
    if not (math.isfinite(L) and L > 0):
        raise ArgumentError(f"linear solution gives no usable camera constant (L = {L!r})")
    alpha, beta, gamma = _angles(C)
    if rho_max is None:
        rho_max = image_diagonal_half / L if image_diagonal_half else 1.0
    return CameraParams(a=a[0], b=a[1], c=a[2], alpha=alpha, beta=beta, gamma=gamma, L=L,
                        R0=R0, T0=T0, rho_max=rho_max)


def _dlt(X: np.ndarray, m: np.ndarray):
    """P (3 x 4) from markers X (n, 3) [m] and centred pixels m (n, 2) [pixel]."""
    mu = X.mean(axis=0)
    sx = float(np.sqrt(np.mean(np.sum((X - mu) ** 2, axis=1)) / 3.0))
    Xn = (X - mu) / sx
    mn, sm = _normalise_image(m)
    n = X.shape[0]
    Xh = np.c_[Xn, np.ones(n)]
    A = np.zeros((2 * n, 12))
    A[0::2, 0:4] = Xh
    A[0::2, 8:12] = -mn[:, :1] * Xh
    A[1::2, 4:8] = Xh
    A[1::2, 8:12] = -mn[:, 1:] * Xh
    Pn = _null_vector(A).reshape(3, 4)
    # undo the normalisations: m = diag(sm, sm, 1) Pn T^-1 X
    T_inv = np.eye(4)
    T_inv[:3, :3] /= sx
    T_inv[:3, 3] = -mu / sx
    return np.diag([sm, sm, 1.0]) @ Pn @ T_inv


def _from_projection(P: np.ndarray, X: np.ndarray):
    """(C, a, L) from P = lam K Q [I | -a]."""
    depth = np.c_[X, np.ones(len(X))] @ P[2]
    if np.mean(depth) < 0:
        P = -P
    M = P[:, :3]
    lam = np.linalg.norm(M[2])
    L = 0.5 * (np.linalg.norm(M[0]) + np.linalg.norm(M[1])) / lam
    C = _nearest_rotation(np.array([M[0] / (lam * L), M[2] / lam, M[1] / (lam * L)]))
    a = -np.linalg.solve(M, P[:, 3])
    return C, a, float(L)


def _plane(X: np.ndarray, m: np.ndarray):
    """(C, a, L) for markers in one plane, by the homography."""
    mu = X.mean(axis=0)
    _, _, vt = np.linalg.svd(X - mu)
    e1, e2 = vt[0], vt[1]
    e3 = np.cross(e1, e2)
    st = np.c_[(X - mu) @ e1, (X - mu) @ e2]
    ss = float(np.sqrt(np.mean(np.sum(st * st, axis=1)) / 2.0))
    stn = st / ss
    mn, sm = _normalise_image(m)
    n = X.shape[0]
    Sh = np.c_[stn, np.ones(n)]
    A = np.zeros((2 * n, 9))
    A[0::2, 0:3] = Sh
    A[0::2, 6:9] = -mn[:, :1] * Sh
    A[1::2, 3:6] = Sh
    A[1::2, 6:9] = -mn[:, 1:] * Sh
    Hn = _null_vector(A).reshape(3, 3)
    H = np.diag([sm, sm, 1.0]) @ Hn @ np.diag([1.0 / ss, 1.0 / ss, 1.0])
    h1, h2, h3 = H[:, 0], H[:, 1], H[:, 2]
    # (h1x h2x + h1y h2y) w + h1z h2z = 0 and (|h1xy|^2 - |h2xy|^2) w + h1z^2 - h2z^2 = 0
    coef = np.array([h1[0] * h2[0] + h1[1] * h2[1], h1[0] ** 2 + h1[1] ** 2 - h2[0] ** 2 - h2[1] ** 2])
    rhs = -np.array([h1[2] * h2[2], h1[2] ** 2 - h2[2] ** 2])
    norm = float(coef @ coef)
    w = float(coef @ rhs) / norm if norm > 0 else 0.0
    if not w > 0.0:
        raise ArgumentError("the marker plane is (nearly) parallel to the image plane: "
                            "the camera constant L cannot be found linearly")
    L = 1.0 / math.sqrt(w)
    Kinv = np.diag([1.0 / L, 1.0 / L, 1.0])
    g1, g2, g3 = Kinv @ h1, Kinv @ h2, Kinv @ h3
    lam = 0.5 * (np.linalg.norm(g1) + np.linalg.norm(g2))
    if g3[2] < 0:                        # depth of the centroid must be positive
        lam = -lam
    q1, q2, q3 = g1 / lam, g2 / lam, g3 / lam
    # Q (det -1) maps e1, e2, e3 = e1 x e2 to q1, q2, -(q1 x q2)
    Q = np.c_[q1, q2, -np.cross(q1, q2)] @ np.c_[e1, e2, e3].T
    C = _nearest_rotation(Q[[0, 2, 1]])
    Q = C[[0, 2, 1]]
    a = mu - Q.T @ q3
    return C, a, float(L)


def starting_guess(markers, pixels, R0: float, T0: float, *, rho_max: float | None = None,
                   image_diagonal_half: float | None = None) -> CameraParams:
    """Ideal camera roughly fitting ``markers`` (n, 3) [m] seen at ``pixels`` (n, 2)
    [pixel], for the optical axis ``(R0, T0)`` [pixel].

    ``rho_max`` [1] is copied into the result; when None it is set to
    ``image_diagonal_half / L`` (so that the improved model's rho stays in [0, 1]).
    Needs >= 6 markers not in one plane, or >= 4 in one plane.
    """
    X = np.asarray(markers, float)
    pix = np.asarray(pixels, float)
    if X.ndim != 2 or X.shape[1] != 3 or pix.shape != (X.shape[0], 2):
        raise ArgumentError(f"markers (n, 3) and pixels (n, 2) expected, got {X.shape}, {pix.shape}")
    n = X.shape[0]
    m = pix - np.array([R0, T0])
    centred = X - X.mean(axis=0)
    if n < 4:
        raise ArgumentError(f"{n} markers; an automatic guess needs at least 4 (in one plane) or 6")
    _, s, vt = np.linalg.svd(centred)
    off_line = np.linalg.norm(centred - np.outer(centred @ vt[0], vt[0]), axis=1).max()
    if off_line < PLANE_TOLERANCE:
        raise ArgumentError("the markers lie on one line: no camera can be found from them")
    off_plane = np.abs(centred @ vt[2]).max()
    if off_plane < PLANE_TOLERANCE:
        C, a, L = _plane(X, m)
    else:
        if n < 6:
            raise ArgumentError(f"{n} markers not in one plane; an automatic guess needs at least 6 "
                                "(or all of them in one plane)")
        C, a, L = _from_projection(_dlt(X, m), X)
    return _camera(C, a, L, R0, T0, rho_max, image_diagonal_half)
