"""Generalized coordinates of the motography rucksack (Hoffmann 1996, eq. 5.1-5.7).

Body frame and LED order
------------------------
The four LEDs sit on a square of side ``2b`` [m] in the body plane ``z_body = 0``.
Eq. 5.4-5.7 fix their order; they imply (``u = (u1, u2, 0)`` body coordinates)::

    LED1 = (+b, +b, 0)   LED2 = (-b, +b, 0)   LED3 = (-b, -b, 0)   LED4 = (+b, -b, 0)

i.e. counter-clockwise seen from above, starting in the (+, +) quadrant, so that LEDs
``j`` and ``j+2`` are diagonal and ``L1 + L3 = L2 + L4``.  The body ``x`` axis (the
"front", zero yaw) points from the LED2/LED3 edge to the LED1/LED4 edge.

Angles
------
Yaw ``psi`` about z, then pitch ``theta`` about the new y axis, then roll ``phi`` about
the new x axis ("similar to an aircraft"), all right-handed with z up [rad]::

    x_i = x0 + R u_i,   R = Rz(psi) Ry(theta) Rx(phi)    (R = B^T of eq. 5.1)

Linearised in ``phi``, ``theta`` the 12 equations are linear in
``q = (x0, y0, z0, phi, theta, cos psi, sin psi)`` and their least-squares solution is
eq. 5.3-5.7 (``psi = atan2(sin psi, cos psi)``).  For large tilts the analytic result
is biased (it returns ``sin theta`` and ``cos theta sin phi``); :func:`fit_nonlinear`
refines it by Gauss-Newton on the exact rigid transform.

Timing
------
The LEDs flash one per 20 ms field in the order 1, 2, 3, 4, so a set spans 80 ms
(12.5 Hz).  :func:`align_to_set_times` interpolates each LED's 3-D track linearly to
the common time of every set (by default the mean of its four field times, i.e. the
LED1 time + 30 ms), removing the up to 60 ms skew between the LEDs of one set, and
bridges a track across one lost sample where the rucksack's geometry confirms it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from marionette.errors import ArgumentError

FIELD_PERIOD = 0.020            # one video field [s]
SET_PERIOD = 4 * FIELD_PERIOD   # one set of four LEDs [s] (12.5 Hz)
SET_TIME_OFFSET = 1.5 * FIELD_PERIOD  # mean field time of a set after LED1 [s]
MAX_SPAN = SET_PERIOD + 0.005   # an LED's samples of neighbouring sets, with timing slack [s]
MAX_BRIDGE = 2 * SET_PERIOD + 0.010   # across one lost sample [s]
BRIDGE_TOLERANCE = 0.030        # bridged point: distances to its set's LEDs within [m]
_SIGNS = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])  # LED1..4 (u1/b, u2/b)


def led_body_coordinates(b: float) -> np.ndarray:
    """Body coordinates of LED1..LED4, shape (4, 3) [m], for half side ``b`` [m]."""
    if not b > 0.0:
        raise ArgumentError(f"rucksack half side b={b!r} m must be > 0")
    u = np.zeros((4, 3))
    u[:, :2] = b * _SIGNS
    return u


def rotation_zyx(phi, theta, psi) -> np.ndarray:
    """``R = Rz(psi) Ry(theta) Rx(phi)`` (body -> object), broadcast, shape (..., 3, 3)."""
    phi, theta, psi = np.broadcast_arrays(*(np.asarray(a, float) for a in (phi, theta, psi)))
    cf, sf = np.cos(phi), np.sin(phi)
    ct, st = np.cos(theta), np.sin(theta)
    cp, sp = np.cos(psi), np.sin(psi)
    R = np.empty(phi.shape + (3, 3))
    R[..., 0, 0] = cp * ct
    R[..., 0, 1] = cp * st * sf - sp * cf
    R[..., 0, 2] = cp * st * cf + sp * sf
    R[..., 1, 0] = sp * ct
    R[..., 1, 1] = sp * st * sf + cp * cf
    R[..., 1, 2] = sp * st * cf - cp * sf
    R[..., 2, 0] = -st
    R[..., 2, 1] = ct * sf
    R[..., 2, 2] = ct * cf
    return R


def angles_from_rotation(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rotation_zyx`: (..., 3) array of (phi, theta, psi) [rad]."""
    R = np.asarray(R, float)
    theta = -np.arcsin(np.clip(R[..., 2, 0], -1.0, 1.0))
    phi = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    psi = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return np.stack([phi, theta, psi], axis=-1)


def led_positions(pose, b: float) -> np.ndarray:
    """LED positions (..., 4, 3) [m] for poses (..., 6) = (x0, y0, z0 [m], phi, theta, psi [rad])."""
    pose = np.asarray(pose, float)
    R = rotation_zyx(pose[..., 3], pose[..., 4], pose[..., 5])
    u = led_body_coordinates(b)
    return pose[..., None, 0:3] + np.einsum("...ij,kj->...ki", R, u)


@dataclass
class RucksackFit:
    """Generalized coordinates of K sets."""

    pose: np.ndarray        # (K, 6): x0, y0, z0 [m], phi, theta, psi [rad]; NaN if missing LEDs
    cos_psi: np.ndarray     # (K,) eq. 5.6 (linear fit) or cos(psi) [1]
    sin_psi: np.ndarray     # (K,) eq. 5.7 (linear fit) or sin(psi) [1]
    residual_m: np.ndarray  # (K,) rms distance between measured and fitted LEDs [m]

    @property
    def scale(self) -> np.ndarray:
        """``hypot(cos psi, sin psi)`` [1]: 1 for a square of the assumed size."""
        return np.hypot(self.cos_psi, self.sin_psi)


def _check_points(points) -> np.ndarray:
    X = np.asarray(points, float)
    if X.shape[-2:] != (4, 3):
        raise ArgumentError(f"LED points must have shape (..., 4, 3) [m], got {X.shape}")
    return X


def _fit_residual(X: np.ndarray, pose: np.ndarray, b: float) -> np.ndarray:
    d = led_positions(pose, b) - X
    return np.sqrt(np.mean(np.sum(d * d, axis=-1), axis=-1))


def fit_linear(points, b: float) -> RucksackFit:
    """Analytic least squares of eq. 5.3-5.7 for LED points (..., 4, 3) [m].

    Sets with a missing (NaN) LED give NaN; complement them first (filters module).
    """
    X = _check_points(points)
    if not b > 0.0:
        raise ArgumentError(f"rucksack half side b={b!r} m must be > 0")
    x, y, z = X[..., 0], X[..., 1], X[..., 2]
    x1, x2, x3, x4 = (x[..., i] for i in range(4))
    y1, y2, y3, y4 = (y[..., i] for i in range(4))
    z1, z2, z3, z4 = (z[..., i] for i in range(4))
    centre = X.mean(axis=-2)                                            # eq. 5.3 [m]
    phi = (z1 - z4 + z2 - z3) / (4.0 * b)                               # eq. 5.4 [rad]
    theta = (z2 - z1 + z3 - z4) / (4.0 * b)                             # eq. 5.5 [rad]
    cos_psi = (x1 - x2 + x4 - x3 + y2 - y3 + y1 - y4) / (8.0 * b)       # eq. 5.6 [1]
    sin_psi = (x3 - x2 + x4 - x1 + y1 - y2 + y4 - y3) / (8.0 * b)       # eq. 5.7 [1]
    psi = np.arctan2(sin_psi, cos_psi)                                  # [rad]
    pose = np.concatenate([centre, np.stack([phi, theta, psi], axis=-1)], axis=-1)
    return RucksackFit(pose, cos_psi, sin_psi, _fit_residual(X, pose, b))


def fit_nonlinear(points, b: float, initial=None, iterations: int = 20, tol: float = 1e-12) -> RucksackFit:
    """Gauss-Newton fit of the exact rigid transform ``x_i = x0 + R(phi, theta, psi) u_i``.

    Starts from :func:`fit_linear` (or ``initial`` poses (..., 6)) and minimises the sum
    of squared LED distances [m^2]; valid for any tilt short of theta = +-90 deg.
    Stops when every step is below ``tol`` (m or rad) or after ``iterations``.
    """
    X = _check_points(points)
    shape = X.shape[:-2]
    Xf = X.reshape(-1, 4, 3)
    start = fit_linear(Xf, b).pose if initial is None else np.asarray(initial, float).reshape(-1, 6)
    # the linear estimates are sin(theta) and cos(theta) sin(phi); take the arcsin
    pose = start.copy()
    if initial is None:
        pose[:, 4] = np.arcsin(np.clip(start[:, 4], -1.0, 1.0))
        pose[:, 3] = np.arcsin(np.clip(start[:, 3] / np.cos(pose[:, 4]), -1.0, 1.0))
    good = np.all(np.isfinite(Xf), axis=(1, 2)) & np.all(np.isfinite(pose), axis=1)
    u = led_body_coordinates(b)
    P = pose[good]
    Xg = Xf[good]
    for _ in range(iterations):
        if P.shape[0] == 0:
            break
        phi, theta, psi = P[:, 3], P[:, 4], P[:, 5]
        cf, sf = np.cos(phi), np.sin(phi)
        ct, st = np.cos(theta), np.sin(theta)
        cp, sp = np.cos(psi), np.sin(psi)
        zero, one = np.zeros_like(phi), np.ones_like(phi)
        Rx = _mat(one, zero, zero, zero, cf, -sf, zero, sf, cf)
        Ry = _mat(ct, zero, st, zero, one, zero, -st, zero, ct)
        Rz = _mat(cp, -sp, zero, sp, cp, zero, zero, zero, one)
        dRx = _mat(zero, zero, zero, zero, -sf, -cf, zero, cf, -sf)
        dRy = _mat(-st, zero, ct, zero, zero, zero, -ct, zero, -st)
        dRz = _mat(-sp, -cp, zero, cp, -sp, zero, zero, zero, zero)
        R = Rz @ Ry @ Rx
        e = P[:, None, 0:3] + np.einsum("kij,lj->kli", R, u) - Xg          # (K, 4, 3) [m]
        J = np.zeros((P.shape[0], 4, 3, 6))
        J[:, :, 0, 0] = 1.0
        J[:, :, 1, 1] = 1.0
        J[:, :, 2, 2] = 1.0
        J[..., 3] = np.einsum("kij,lj->kli", Rz @ Ry @ dRx, u)
        J[..., 4] = np.einsum("kij,lj->kli", Rz @ dRy @ Rx, u)
        J[..., 5] = np.einsum("kij,lj->kli", dRz @ Ry @ Rx, u)
        J = J.reshape(P.shape[0], 12, 6)
        e = e.reshape(P.shape[0], 12)
        normal = np.einsum("kri,krj->kij", J, J)                           # (K, 6, 6)
        step = np.linalg.solve(normal, -np.einsum("kri,kr->ki", J, e)[..., None])[..., 0]
        P = P + step
        if np.max(np.abs(step)) < tol:
            break
    P[:, 5] = (P[:, 5] + np.pi) % (2.0 * np.pi) - np.pi
    pose = np.full((Xf.shape[0], 6), np.nan)
    pose[good] = P
    res = _fit_residual(Xf, pose, b)
    return RucksackFit(
        pose.reshape(shape + (6,)),
        np.cos(pose[:, 5]).reshape(shape),
        np.sin(pose[:, 5]).reshape(shape),
        res.reshape(shape),
    )


def _mat(*entries) -> np.ndarray:
    """Stack 9 arrays (K,) row by row into (K, 3, 3)."""
    return np.stack(entries, axis=-1).reshape(entries[0].shape + (3, 3))


# ----------------------------------------------------------------------------------
# Strobe timing: one LED per field
# ----------------------------------------------------------------------------------
def set_times(led1_time: float, n_sets: int, offset: float = SET_TIME_OFFSET) -> np.ndarray:
    """Common times [s] of ``n_sets`` sets whose first LED1 field is at ``led1_time`` [s]."""
    return led1_time + offset + SET_PERIOD * np.arange(n_sets)


def _cubic(t, T, X):
    """Lagrange cubic through samples at times T (n, 4) [s], points X (n, 4, 3) [m],
    evaluated at times t (n,) [s]."""
    w = np.ones(T.shape)
    for a in range(4):
        for b in range(4):
            if a != b:
                w[:, a] *= (t - T[:, b]) / (T[:, a] - T[:, b])
    return np.einsum("na,nai->ni", w, X)


def align_to_set_times(times, leds, points, common_times=None, *, half_side: float | None = None,
                       max_span: float = MAX_SPAN, max_bridge: float = MAX_BRIDGE,
                       bridge_tolerance: float = BRIDGE_TOLERANCE):
    """Interpolate each LED's 3-D track to the common time of every set.

    ``times`` (M,) [s], ``leds`` (M,) LED numbers 1..4, ``points`` (M, 3) [m] (NaN for a
    detection that could not be triangulated).  ``common_times`` (K,) [s] defaults to
    :func:`set_times` starting at the first LED1 detection and covering the data.
    An LED's value at time t is the linear interpolation between its nearest valid
    samples before and after t, if those are at most ``max_span`` [s] apart (default:
    neighbouring sets only); otherwise NaN, which the syntactic filter may complement.

    With the rucksack's ``half_side`` b [m], a track is also bridged across one lost
    sample (its samples at most ``max_bridge`` [s] apart) where its neighbours allow
    it: with a valid sample within ``max_span`` before and after the gap, the value is
    the cubic through those four samples, kept only if the rucksack agrees: its
    distances to the LEDs of its set that were not bridged (at least two) are within
    ``bridge_tolerance`` [m] of the square's, 2b to a neighbour and 2 sqrt(2) b across.

    Returns ``(common_times (K,), points (K, 4, 3))``.
    """
    t = np.asarray(times, float)
    led = np.asarray(leds)
    X = np.asarray(points, float)
    if t.ndim != 1 or led.shape != t.shape or X.shape != t.shape + (3,):
        raise ArgumentError("times (M,), leds (M,) and points (M, 3) must agree in length")
    if np.any(np.diff(t) < 0):
        raise ArgumentError("times must be non-decreasing")
    bad = ~np.isin(led, (1, 2, 3, 4))
    if np.any(bad):
        raise ArgumentError(f"LED number {int(led[bad][0])} is not one of 1, 2, 3, 4")
    if common_times is None:
        first = t[led == 1]
        if first.size == 0:
            raise ArgumentError("no LED1 detection: cannot place the set times; pass common_times")
        n = int(np.floor((t[-1] - first[0]) / SET_PERIOD)) + 1
        common_times = set_times(first[0], n)
    tc = np.asarray(common_times, float)
    out = np.full((tc.size, 4, 3), np.nan)
    bridged = np.full((tc.size, 4, 3), np.nan)      # candidates across one lost sample [m]
    for j in range(4):
        sel = (led == j + 1) & np.all(np.isfinite(X), axis=1)
        tj, Xj = t[sel], X[sel]
        if tj.size == 0:
            continue
        hi = np.searchsorted(tj, tc, side="left")            # first sample >= t
        lo = hi - 1
        exact = (hi < tj.size) & (tj[np.minimum(hi, tj.size - 1)] == tc)
        inside = (lo >= 0) & (hi < tj.size)
        loc = np.clip(lo, 0, tj.size - 1)
        hic = np.clip(hi, 0, tj.size - 1)
        span = tj[hic] - tj[loc]
        use = inside & (span <= max_span) & (span > 0)
        with np.errstate(invalid="ignore", divide="ignore"):
            w = np.where(use, (tc - tj[loc]) / np.where(span > 0, span, 1.0), 0.0)
        val = (1.0 - w)[:, None] * Xj[loc] + w[:, None] * Xj[hic]
        out[use, j] = val[use]
        out[exact, j] = Xj[hic[exact]]
        if half_side is None:
            continue
        gap = inside & ~use & ~exact & (span <= max_bridge) & (lo >= 1) & (hi + 1 < tj.size)
        k = np.flatnonzero(gap)
        idx = lo[k, None] + np.arange(-1, 3)                # (n, 4) two samples either side
        near = (tj[idx[:, 1]] - tj[idx[:, 0]] <= max_span) & (tj[idx[:, 3]] - tj[idx[:, 2]] <= max_span)
        bridged[k[near], j] = _cubic(tc[k[near]], tj[idx[near]], Xj[idx[near]])
    if half_side is not None:
        side, across = 2.0 * half_side, 2.0 * math.sqrt(2.0) * half_side
        square = np.array([[0, side, across, side], [side, 0, side, across],
                           [across, side, 0, side], [side, across, side, 0]])   # LED distances [m]
        seen = np.isfinite(out[..., 0])                                      # (K, 4)
        dist = np.linalg.norm(bridged[:, :, None] - out[:, None, :], axis=-1)  # (K, 4, 4) [m]
        worst = np.max(np.where(seen[:, None, :], np.abs(dist - square), 0.0), axis=2)
        ok = np.isfinite(bridged[..., 0]) & (seen.sum(axis=1) >= 2)[:, None] & (worst <= bridge_tolerance)
        out[ok] = bridged[ok]
    return tc, out


def group_sets(times, leds, points, common_times=None):
    """Naive grouping without time correction: the LED j of set k is the detection in
    field ``4k + j - 1`` after the first LED1, assigned to the set's common time.

    For comparison with :func:`align_to_set_times`; returns the same shapes.  Sets are
    counted from the first LED1 detection (also when ``common_times`` is given).
    """
    t = np.asarray(times, float)
    led = np.asarray(leds)
    X = np.asarray(points, float)
    first = t[led == 1]
    if first.size == 0:
        raise ArgumentError("no LED1 detection")
    if common_times is None:
        n = int(np.floor((t[-1] - first[0]) / SET_PERIOD)) + 1
        common_times = set_times(first[0], n)
    tc = np.asarray(common_times, float)
    out = np.full((tc.size, 4, 3), np.nan)
    k = np.floor((t - first[0]) / SET_PERIOD + 1e-6).astype(int)
    ok = (k >= 0) & (k < tc.size)
    out[k[ok], led[ok] - 1] = X[ok]
    return tc, out
