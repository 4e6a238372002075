"""Identification of camera parameters from known markers (Hoffmann 1996, eq. 4.8-4.9).

For every marker ``i`` with known object coordinates ``x_i`` [m] and measured pixels
``(R_i, T_i)`` [pixel] the error of eq. 4.8 is

    eps_i = A_i C (x_i - a) = (-u_i + (r_i/d) v_i,  (t_i/d) v_i - w_i)     [m]

where ``A_i`` (eq. 4.5) is filled with the ideal image coordinates of the measured
pixels (improved model, eq. 4.15-4.23) and ``(u, v, w) = C (x - a)``.  The scalar
``F = sum eps_i^T eps_i`` [m^2] (eq. 4.9) is minimised over the free parameters
(default the ideal camera's ``p = (a, b, c, alpha, beta, gamma, L)``).  Optionally the
residual can be the reprojection error in pixels instead (``residual="pixel"``,
``F`` then in pixel^2).

Two solvers:

* :func:`calibrate_steepest_descent` - the paper's method: steepest descent on ``F``
  in scaled parameters ``z = p / s`` with ``s_k = 1/|column k of J|`` at the start,
  an adaptive step (doubled after success, halved after failure).  Slow but reliable.
* :func:`calibrate_lm` - Levenberg-Marquardt with Marquardt's diagonal damping; it
  converges in far fewer iterations.

Both need a starting guess (camera position to within a metre or so, angles to within
~0.2 rad, L within a factor ~1.5): F is not convex, and a guess with markers behind the
camera or a mirror-image pose converges to a wrong minimum or not at all.
The Jacobian is computed by central differences (one vectorised evaluation).
Marker sets that cannot identify the free parameters are refused with ``ValueError``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .camera import (
    ALL_NAMES,
    IDEAL_PARAMETER_NAMES,
    PARAMETER_NAMES,
    CameraParams,
    ideal_to_pixel_arrays,
    pixel_to_ideal_arrays,
    project,
    rotation_matrix,
)
from marionette.errors import ArgumentError

MIN_MARKERS = 5                 # eq. 4.8 is written for n = 5 markers
DEFAULT_MAX_CONDITION = 1e10    # limit of cond(D J^T J D), D = column scaling [1]
MIN_SEPARATION = 1e-3           # markers closer than this are duplicates [m]
LINE_TOLERANCE = 1e-3           # max distance from a line/plane to count as on it [m]

_INDEX = {n: i for i, n in enumerate(ALL_NAMES)}


@dataclass
class CalibrationResult:
    """Outcome of a calibration."""

    params: CameraParams            # identified camera
    free: tuple[str, ...]           # names of the estimated parameters
    method: str                     # "steepest_descent" or "levenberg_marquardt"
    residual_kind: str              # "algebraic" (eq. 4.8, m) or "pixel"
    F: float                        # sum of squared residuals [m^2] or [pixel^2]
    rms_px: float                   # rms reprojection error over all coordinates [pixel]
    iterations: int                 # outer iterations (Jacobian evaluations)
    evaluations: int                # residual evaluations incl. line search / damping
    converged: bool                 # a convergence test was met before max_iter
    uncertainty: dict[str, float]   # standard uncertainty per free parameter [its unit]
    covariance: np.ndarray          # covariance of the free parameters
    condition: float                # cond of the scaled J^T J at the solution [1]
    residuals_px: np.ndarray = field(repr=False, default=None)  # (n, 2) reprojection error


# ----------------------------------------------------------------------------------
# Residuals and Jacobian
# ----------------------------------------------------------------------------------
def _residual_batch(P: np.ndarray, X: np.ndarray, pix: np.ndarray, kind: str) -> np.ndarray:
    """Residual vectors for a batch of full parameter vectors.

    ``P`` (B, 14) in :data:`ALL_NAMES` order, ``X`` (n, 3) [m], ``pix`` (n, 2) [pixel].
    Returns (B, 2n): eq. 4.8 errors [m] or reprojection errors [pixel].
    """
    col = {n: P[:, i:i + 1] for n, i in _INDEX.items()}        # each (B, 1)
    C = rotation_matrix(P[:, _INDEX["alpha"]], P[:, _INDEX["beta"]], P[:, _INDEX["gamma"]])
    d = X[None, :, :] - P[:, None, 0:3]                          # (B, n, 3) [m]
    uvw = np.einsum("bij,bnj->bni", C, d)                        # (B, n, 3) [m]
    u, v, w = uvw[..., 0], uvw[..., 1], uvw[..., 2]
    dist = [col[n] for n in ("R0", "T0", "L", "delta", "epsilon", "q3", "q5", "rho_max")]
    if kind == "algebraic":
        rd, td = pixel_to_ideal_arrays(pix[None, :, 0], pix[None, :, 1], *dist)
        e = np.stack([-u + rd * v, td * v - w], axis=-1)         # eq. 4.8 [m]
    else:
        with np.errstate(divide="ignore", invalid="ignore"):
            R, T = ideal_to_pixel_arrays(u / v, w / v, *dist)
        e = np.stack([R - pix[None, :, 0], T - pix[None, :, 1]], axis=-1)  # [pixel]
        e[np.broadcast_to((v <= 0)[..., None], e.shape)] = np.nan
    return e.reshape(P.shape[0], -1)


def _steps(p_free: np.ndarray, free: Sequence[str]) -> np.ndarray:
    """Central-difference steps per free parameter (relative 1e-6, absolute floor)."""
    typical = np.array([1.0 if n not in ("q3", "q5") else 0.1 for n in free])
    return 1e-6 * (np.abs(p_free) + typical)


class _Problem:
    """Free-parameter view of the calibration problem."""

    def __init__(self, X, pix, base: CameraParams, free: Sequence[str], kind: str):
        self.X = X
        self.pix = pix
        self.free = tuple(free)
        self.kind = kind
        self.full = base.to_vector(ALL_NAMES)
        self.idx = np.array([_INDEX[n] for n in self.free])
        self.evaluations = 0

    def expand(self, p_free: np.ndarray) -> np.ndarray:
        full = np.repeat(self.full[None, :], p_free.shape[0], axis=0)
        full[:, self.idx] = p_free
        return full

    def residual(self, p: np.ndarray) -> np.ndarray:
        self.evaluations += 1
        return _residual_batch(self.expand(p[None, :]), self.X, self.pix, self.kind)[0]

    def jacobian(self, p: np.ndarray) -> np.ndarray:
        h = _steps(p, self.free)
        k = len(p)
        batch = np.repeat(p[None, :], 2 * k, axis=0)
        batch[np.arange(k), np.arange(k)] += h
        batch[k + np.arange(k), np.arange(k)] -= h
        self.evaluations += 1
        r = _residual_batch(self.expand(batch), self.X, self.pix, self.kind)
        return ((r[:k] - r[k:]) / (2.0 * h[:, None])).T           # (2n, k)

    def camera(self, p: np.ndarray) -> CameraParams:
        full = self.full.copy()
        full[self.idx] = p
        for name in ("alpha", "beta", "gamma"):
            i = _INDEX[name]
            full[i] = (full[i] + np.pi) % (2.0 * np.pi) - np.pi  # wrap to [-pi, pi) [rad]
        return CameraParams.from_vector(full, ALL_NAMES)


def _sum_sq(r: np.ndarray) -> float:
    return float(r @ r) if np.all(np.isfinite(r)) else np.inf


# ----------------------------------------------------------------------------------
# Input checks
# ----------------------------------------------------------------------------------
def _label(labels, i) -> str:
    return str(labels[i]) if labels is not None else str(i)


def _check_inputs(markers, pixels, free, labels):
    X = np.asarray(markers, float)
    pix = np.asarray(pixels, float)
    if X.ndim != 2 or X.shape[1] != 3:
        raise ArgumentError(f"markers must have shape (n, 3) [m], got {X.shape}")
    if pix.shape != (X.shape[0], 2):
        raise ArgumentError(f"pixels must have shape ({X.shape[0]}, 2) [pixel], got {pix.shape}")
    if labels is not None and len(labels) != X.shape[0]:
        raise ArgumentError(f"{len(labels)} labels given for {X.shape[0]} markers")
    bad_names = [n for n in free if n not in PARAMETER_NAMES]
    if bad_names:
        raise ArgumentError(f"cannot estimate {bad_names}; estimable: {list(PARAMETER_NAMES)}")
    if len(set(free)) != len(free) or not free:
        raise ArgumentError(f"free parameters must be unique and non-empty, got {list(free)}")
    n = X.shape[0]
    for i in range(n):
        if not np.all(np.isfinite(X[i])):
            raise ArgumentError(f"marker {_label(labels, i)}: position {X[i].tolist()} is not finite")
        if not np.all(np.isfinite(pix[i])):
            raise ArgumentError(f"marker {_label(labels, i)}: pixels {pix[i].tolist()} are not finite")
    if n < MIN_MARKERS:
        raise ArgumentError(f"calibration needs at least {MIN_MARKERS} markers, got {n}")
    if 2 * n <= len(free):
        raise ArgumentError(
            f"{n} markers give {2 * n} equations, not enough for {len(free)} free "
            f"parameters {list(free)}; use at least {len(free) // 2 + 1} markers"
        )
    for i in range(n):
        for j in range(i + 1, n):
            if np.linalg.norm(X[i] - X[j]) < MIN_SEPARATION:
                raise ArgumentError(
                    f"markers {_label(labels, i)} and {_label(labels, j)} coincide "
                    f"(closer than {MIN_SEPARATION} m)"
                )
    centred = X - X.mean(axis=0)
    _, s, vt = np.linalg.svd(centred, full_matrices=False)
    off_line = np.linalg.norm(centred - np.outer(centred @ vt[0], vt[0]), axis=1)
    if off_line.max() < LINE_TOLERANCE:
        names = ", ".join(_label(labels, i) for i in range(n))
        raise ArgumentError(
            f"markers {names} are collinear (all within {LINE_TOLERANCE} m of one line): "
            "the rotation about that line cannot be identified"
        )
    return X, pix


def _geometry_note(X, labels) -> str:
    centred = X - X.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    off_plane = np.abs(centred @ vt[2])
    if off_plane.max() < LINE_TOLERANCE:
        names = ", ".join(_label(labels, i) for i in range(X.shape[0]))
        return f"; markers {names} are coplanar (all within {LINE_TOLERANCE} m of one plane)"
    return ""


def _scaled_condition(J: np.ndarray):
    """Condition number of D J^T J D (D makes the diagonal 1) and the weakest direction."""
    norms = np.linalg.norm(J, axis=0)
    if np.any(norms == 0.0) or not np.all(np.isfinite(J)):
        return np.inf, (norms == 0.0).astype(float)
    Js = J / norms
    eig, vec = np.linalg.eigh(Js.T @ Js)
    cond = eig[-1] / eig[0] if eig[0] > 0.0 else np.inf
    return float(cond), vec[:, 0]


def _check_condition(J, free, X, labels, max_condition, where):
    cond, weak = _scaled_condition(J)
    if cond > max_condition:
        order = np.argsort(-np.abs(weak))
        combo = " ".join(f"{weak[k]:+.2f}*{free[k]}" for k in order[:4] if abs(weak[k]) > 0.05)
        raise ArgumentError(
            f"ill-conditioned camera calibration at the {where}: condition number of the "
            f"scaled J^T J is {cond:.3g} (limit {max_condition:.3g}); parameters "
            f"{[free[k] for k in order[:4] if abs(weak[k]) > 0.05]} are not separately "
            f"identifiable (weakest combination {combo}){_geometry_note(X, labels)}"
        )
    return cond


def _check_in_front(cam: CameraParams, X, labels, where):
    uvw = (X - cam.position) @ cam.rotation.T
    behind = np.nonzero(uvw[:, 1] <= 0.0)[0]
    if behind.size:
        names = ", ".join(_label(labels, i) for i in behind)
        raise ArgumentError(f"markers {names} are behind the camera at the {where}")


# ----------------------------------------------------------------------------------
# Solvers
# ----------------------------------------------------------------------------------
def _gradient_cosine(J: np.ndarray, r: np.ndarray) -> float:
    """max_k |J_k . r| / (|J_k| |r|): 0 at a stationary point [1]."""
    rn = np.linalg.norm(r)
    if rn == 0.0:
        return 0.0
    return float(np.max(np.abs(J.T @ r) / (np.linalg.norm(J, axis=0) * rn)))


def _prepare(markers, pixels, guess, free, labels, residual, max_condition):
    if residual not in ("algebraic", "pixel"):
        raise ArgumentError(f"residual must be 'algebraic' or 'pixel', got {residual!r}")
    if not isinstance(guess, CameraParams):
        raise TypeError("guess must be a CameraParams (a starting guess is required)")
    free = tuple(free)
    X, pix = _check_inputs(markers, pixels, free, labels)
    _check_in_front(guess, X, labels, "starting guess")
    prob = _Problem(X, pix, guess, free, residual)
    p = guess.to_vector(free)
    r = prob.residual(p)
    if not np.all(np.isfinite(r)):
        raise ArgumentError("residual at the starting guess is not finite; check the guess")
    J = prob.jacobian(p)
    _check_condition(J, free, X, labels, max_condition, "starting guess")
    return prob, p, r, J


def _finish(prob, p, method, iterations, converged, labels, max_condition) -> CalibrationResult:
    cam = prob.camera(p)
    _check_in_front(cam, prob.X, labels, "solution")
    r = prob.residual(p)
    J = prob.jacobian(p)
    cond = _check_condition(J, prob.free, prob.X, labels, max_condition, "solution")
    F = _sum_sq(r)
    dof = r.size - len(p)
    sigma2 = F / dof                                    # residual variance [unit^2]
    cov = sigma2 * np.linalg.inv(J.T @ J)
    res_px = project(cam, prob.X) - prob.pix
    return CalibrationResult(
        params=cam,
        free=prob.free,
        method=method,
        residual_kind=prob.kind,
        F=F,
        rms_px=float(np.sqrt(np.mean(res_px**2))),
        iterations=iterations,
        evaluations=prob.evaluations,
        converged=converged,
        uncertainty={n: float(np.sqrt(cov[k, k])) for k, n in enumerate(prob.free)},
        covariance=cov,
        condition=cond,
        residuals_px=res_px,
    )


def calibrate_lm(
    markers,
    pixels,
    guess: CameraParams,
    free: Sequence[str] = IDEAL_PARAMETER_NAMES,
    *,
    residual: str = "algebraic",
    labels: Sequence[str] | None = None,
    max_iter: int = 200,
    gtol: float = 1e-9,
    xtol: float = 1e-12,
    max_condition: float = DEFAULT_MAX_CONDITION,
) -> CalibrationResult:
    """Levenberg-Marquardt minimisation of F (eq. 4.9).

    ``markers`` (n, 3) [m], ``pixels`` (n, 2) [pixel], ``guess`` the starting camera
    (its non-free parameters, e.g. R0, T0, rho_max, are kept).  Damping: solve
    ``(J^T J + lam diag(J^T J)) dp = -J^T r``; lam /10 on success, x10 on failure.
    Stops when the gradient cosine (see :func:`_gradient_cosine`) < ``gtol`` or the
    relative step < ``xtol``.
    """
    prob, p, r, J = _prepare(markers, pixels, guess, free, labels, residual, max_condition)
    F = _sum_sq(r)
    lam = 1e-3
    converged = False
    it = 0
    while it < max_iter:
        it += 1
        if it > 1:
            J = prob.jacobian(p)
        if _gradient_cosine(J, r) < gtol:
            converged = True
            break
        A = J.T @ J
        g = J.T @ r
        diag = np.diag(A).copy()
        step_ok = False
        while lam < 1e16:
            try:
                dp = np.linalg.solve(A + lam * np.diag(diag), -g)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            r_new = prob.residual(p + dp)
            F_new = _sum_sq(r_new)
            if F_new < F:
                step_ok = True
                break
            lam *= 10.0
        if not step_ok:
            converged = True        # no descent possible: at a minimum to rounding
            break
        small = np.all(np.abs(dp) <= xtol * (np.abs(p) + 1.0))
        p, r, F = p + dp, r_new, F_new
        lam = max(lam / 10.0, 1e-12)
        if small or F == 0.0:
            converged = True
            break
    return _finish(prob, p, "levenberg_marquardt", it, converged, labels, max_condition)


def calibrate_steepest_descent(
    markers,
    pixels,
    guess: CameraParams,
    free: Sequence[str] = IDEAL_PARAMETER_NAMES,
    *,
    residual: str = "algebraic",
    labels: Sequence[str] | None = None,
    scale: Sequence[float] | None = None,
    max_iter: int = 20000,
    gtol: float = 1e-6,
    max_condition: float = DEFAULT_MAX_CONDITION,
) -> CalibrationResult:
    """The paper's steepest descent on F (eq. 4.9) with parameter scaling.

    Scaled parameters ``z_k = p_k / s_k``; by default ``s_k = 1/|J_k|`` (column norm of
    the Jacobian at the guess, so that every ``z_k`` moves F equally), or ``scale``
    [unit of each free parameter].  Step ``dz = -h grad_z F`` with ``h`` doubled after a
    successful and halved after a failed step.  Stops when the gradient cosine < ``gtol``
    or ``h`` underflows; slow on elongated valleys, hence the generous ``max_iter``.
    """
    prob, p, r, J = _prepare(markers, pixels, guess, free, labels, residual, max_condition)
    if scale is None:
        s = 1.0 / np.linalg.norm(J, axis=0)
    else:
        s = np.asarray(scale, float)
        if s.shape != p.shape or np.any(s <= 0):
            raise ArgumentError(f"scale must be {len(p)} positive numbers, one per free parameter")
    F = _sum_sq(r)
    h = 0.1
    converged = False
    it = 0
    while it < max_iter:
        it += 1
        if it > 1:
            J = prob.jacobian(p)
        if _gradient_cosine(J, r) < gtol or F == 0.0:
            converged = True
            break
        gz = 2.0 * s * (J.T @ r)                   # dF/dz [F unit]
        while True:
            dp = -h * s * gz                       # dp = s dz [unit of p]
            r_new = prob.residual(p + dp)
            F_new = _sum_sq(r_new)
            if F_new < F:
                break
            h *= 0.5
            if h < 1e-18:
                break
        if h < 1e-18:
            converged = True                       # no descent along the gradient
            break
        p, r, F = p + dp, r_new, F_new
        h *= 2.0
    return _finish(prob, p, "steepest_descent", it, converged, labels, max_condition)


def calibrate(markers, pixels, guess: CameraParams, method: str = "lm", **kwargs) -> CalibrationResult:
    """Dispatch to :func:`calibrate_lm` (``"lm"``) or :func:`calibrate_steepest_descent`
    (``"steepest_descent"``)."""
    if method == "lm":
        return calibrate_lm(markers, pixels, guess, **kwargs)
    if method == "steepest_descent":
        return calibrate_steepest_descent(markers, pixels, guess, **kwargs)
    raise ArgumentError(f"unknown calibration method {method!r}; use 'lm' or 'steepest_descent'")


__all__ = [
    "CalibrationResult",
    "calibrate",
    "calibrate_lm",
    "calibrate_steepest_descent",
]
