"""Object points from two or more cameras (Hoffmann 1996, eq. 4.10-4.14).

Each camera ``k`` that sees the point contributes the two rows of eq. 4.10,

    A^k C^k x = A^k C^k a^k          (A^k of eq. 4.5 from the measured pixels),

and all rows together form ``M x = N b`` (eq. 4.11-4.12), 2K equations for the three
coordinates ``x`` [m].  The least-squares compromise solves the normal equations
``M^T M x = M^T N b`` (eq. 4.13) with the Cholesky factorisation ``M^T M = G G^T``
(``numpy.linalg.cholesky``) followed by a forward and a backward triangular solve.
``M^T M`` (3 x 3, dimensionless) is accumulated camera by camera, so the same code
serves two cameras (the paper) or any number, and missing detections (NaN pixels)
simply leave their camera out for that point.  Everything is vectorised over points.

The quality measure is the reprojection error: for every camera used, the difference
between the measured and the re-projected ideal image coordinates, times L, gives an
error in (ideal) pixels; ``residual_px`` is its rms over the 2K coordinates.  A pair of
detections that do not belong to one point (a reflection, a wrong LED) shows up as a
residual of many pixels, because the two view lines then miss each other.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .camera import CameraParams, homogeneous_matrix, pixel_to_ideal
from marionette.errors import ArgumentError

DEFAULT_MAX_RESIDUAL_PX = 3.0   # flag points whose rms reprojection error exceeds this [pixel]
DEFAULT_MAX_CONDITION = 1e8     # refuse near-parallel view lines: cond(M^T M) limit [1]


@dataclass
class Triangulation:
    """Result of :func:`triangulate` for N points."""

    points: np.ndarray       # (N, 3) object coordinates [m]; NaN where not computable
    residual_px: np.ndarray  # (N,) rms reprojection error over the used cameras [pixel]
    n_cameras: np.ndarray    # (N,) number of cameras that saw the point [1]
    ok: np.ndarray           # (N,) bool: point computed and residual_px <= threshold


def forward_substitution(G: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve ``G y = b`` for lower-triangular ``G`` (N, n, n) and ``b`` (N, n)."""
    n = G.shape[-1]
    y = np.empty_like(b)
    for i in range(n):
        y[:, i] = (b[:, i] - np.einsum("nj,nj->n", G[:, i, :i], y[:, :i])) / G[:, i, i]
    return y


def backward_substitution(G: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Solve ``G^T x = y`` for lower-triangular ``G`` (N, n, n) and ``y`` (N, n)."""
    n = G.shape[-1]
    x = np.empty_like(y)
    for i in range(n - 1, -1, -1):
        x[:, i] = (y[:, i] - np.einsum("nj,nj->n", G[:, i + 1:, i], x[:, i + 1:])) / G[:, i, i]
    return x


def cholesky_solve(S: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve symmetric positive definite systems ``S x = rhs``, S (N, n, n), rhs (N, n)."""
    G = np.linalg.cholesky(S)          # S = G G^T, G lower triangular
    return backward_substitution(G, forward_substitution(G, rhs))


def triangulate(
    cameras: Sequence[CameraParams],
    pixels,
    *,
    max_residual_px: float = DEFAULT_MAX_RESIDUAL_PX,
    max_condition: float = DEFAULT_MAX_CONDITION,
) -> Triangulation:
    """Triangulate N points seen by K cameras.

    ``pixels`` has shape (K, N, 2) (or (K, 2) for one point): ``(R, T)`` [pixel] of the
    point in camera k, NaN where camera k did not see it.  Points seen by fewer than two
    cameras, or whose view lines are nearly parallel (cond(M^T M) > ``max_condition``),
    come back as NaN with ``ok`` False.
    """
    pix = np.asarray(pixels, float)
    single = pix.ndim == 2
    if single:
        pix = pix[:, None, :]
    if pix.ndim != 3 or pix.shape[-1] != 2 or pix.shape[0] != len(cameras):
        raise ArgumentError(
            f"pixels must have shape (K={len(cameras)}, N, 2) [pixel], got {np.shape(pixels)}"
        )
    K, N = pix.shape[0], pix.shape[1]
    MtM = np.zeros((N, 3, 3))           # sum over cameras of (A C)^T (A C) [1]
    MtNb = np.zeros((N, 3))             # sum over cameras of (A C)^T (A C a) [m]
    seen = np.zeros((K, N), bool)
    ideal = np.full((K, N, 2), np.nan)
    for k, cam in enumerate(cameras):
        seen[k] = np.all(np.isfinite(pix[k]), axis=-1)
        ideal[k] = pixel_to_ideal(cam, np.where(seen[k][:, None], pix[k], cam.R0))
        AC = homogeneous_matrix(ideal[k]) @ cam.rotation          # (N, 2, 3) [1]
        rhs = AC @ cam.position                                     # (N, 2) [m]
        w = seen[k].astype(float)
        MtM += w[:, None, None] * np.einsum("nki,nkj->nij", AC, AC)
        MtNb += w[:, None] * np.einsum("nki,nk->ni", AC, rhs)
    n_cam = seen.sum(axis=0)
    solvable = n_cam >= 2
    if np.any(solvable):
        eig = np.linalg.eigvalsh(MtM[solvable])
        with np.errstate(divide="ignore"):
            cond = np.where(eig[:, 0] > 0.0, eig[:, -1] / eig[:, 0], np.inf)
        idx = np.nonzero(solvable)[0]
        solvable[idx[cond > max_condition]] = False
    points = np.full((N, 3), np.nan)
    if np.any(solvable):
        points[solvable] = cholesky_solve(MtM[solvable], MtNb[solvable])   # eq. 4.13-4.14
    # reprojection residual in ideal pixels: L * (projected - measured ideal coordinates)
    sq = np.zeros(N)
    for k, cam in enumerate(cameras):
        uvw = (points - cam.position) @ cam.rotation.T
        v = uvw[:, 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            err = cam.L * (np.stack([uvw[:, 0] / v, uvw[:, 2] / v], axis=-1) - ideal[k])
        e2 = np.sum(err**2, axis=-1)
        e2 = np.where(v > 0.0, e2, np.inf)           # behind the camera: not a solution
        sq += np.where(seen[k] & solvable, e2, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        residual = np.where(solvable, np.sqrt(sq / (2.0 * np.maximum(n_cam, 1))), np.nan)
    ok = solvable & (residual <= max_residual_px)
    if single:
        return Triangulation(points[0], residual[0], n_cam[0], ok[0])
    return Triangulation(points, residual, n_cam, ok)


def triangulate_pair(cam1: CameraParams, cam2: CameraParams, pixels1, pixels2, **kwargs) -> Triangulation:
    """Two-camera form of eq. 4.10-4.14; ``pixels1``, ``pixels2`` (N, 2) [pixel]."""
    return triangulate([cam1, cam2], np.stack([np.asarray(pixels1, float), np.asarray(pixels2, float)]),
                       **kwargs)
