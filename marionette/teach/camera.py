"""Camera model of the teach-in photogrammetry (Hoffmann 1996, eq. 4.1-4.7, 4.15-4.23).

Conventions
-----------
* Object space ``x = (x, y, z)`` [m], right-handed, ``z`` up.
* Camera position ``(a, b, c)`` [m]; angles [rad]: yaw ``gamma`` about ``z``, then
  elevation ``alpha``, then roll ``beta`` (matrix ``C`` of eq. 4.3, ``C = Rb Ra Rg``).
* Camera frame ``(u, v, w) = C (x - a)`` [m]: ``v`` is the depth along the view line,
  ``u`` points to the right of the image, ``w`` up.  With all angles zero the camera
  looks along ``+y``.
* Ideal image coordinates are the dimensionless ratios ``r/d = u/v`` and ``t/d = w/v``
  (eq. 4.4, ``d`` is the image distance, which never has to be known).
* Pixels: ``R`` is the column number (grows with ``u``, to the right) and ``T`` the row
  number (grows with ``w``, i.e. *upwards*), both [pixel]; for the ideal camera
  ``R = R0 + L r/d`` and ``T = T0 + L t/d`` (eq. 4.2).  A tracker that counts rows
  downwards must be converted (``T = rows - 1 - row``) before its data enter here.
* This is self-consistent with the homogeneous form ``A C (x - a) = 0`` of eq. 4.5-4.7:
  with ``A = [[-1, r/d, 0], [0, t/d, -1]]`` the two rows read ``-u + (r/d) v = 0`` and
  ``(t/d) v - w = 0``.

Improved (non-ideal) model, eq. 4.15-4.23, maps measured pixels ``(F, H)`` (called
``R, T`` here as well) to ideal image coordinates:

    f1 = (R - R0)/L,           h1 = (T - T0)/L                     (4.15)
    f2 = f1 - epsilon,         h2 = h1 + delta                     (4.16)
    rho = sqrt(f2^2 + h2^2) / rho_max                              (4.17)
    Q3 = (5 rho^3 - 3 rho)/2,  Q5 = (63 rho^5 - 70 rho^3 + 15 rho)/8 (4.18)
    Kp = 1 + q3 Q3/rho + q5 Q5/rho                                 (4.19)
    f3 = Kp f2,                h3 = Kp h2                          (4.20)
    f4 = f3 + epsilon,         h4 = h3 - delta                     (4.21)
    r/d = f4 / (1 + f4 epsilon - h4 delta)                         (4.22)
    t/d = h4 / (1 + f4 epsilon - h4 delta)                         (4.23)

All ``f``, ``h`` are ratios to the image distance ``d`` [1].  The printed eq. 4.21
reads ``h4/d = Kp h3/d - delta``; applying ``Kp`` twice to ``h`` but once to ``f`` is
taken as a misprint, and ``h4 = h3 - delta`` (undoing the shift of eq. 4.16) is used.
``Q3/rho`` and ``Q5/rho`` are evaluated as polynomials so that ``rho = 0`` is regular.
The inverse map (ideal -> pixel, used for projection and simulation) is solved in
closed form except for the radial step, which is a scalar Newton iteration.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Iterable, Mapping, Sequence

import numpy as np

from marionette.errors import ArgumentError

# Names of the parameters that calibration may estimate, in vector order.
PARAMETER_NAMES: tuple[str, ...] = (
    "a", "b", "c",            # camera position [m]
    "alpha", "beta", "gamma",  # elevation, roll, yaw [rad]
    "L",                      # camera constant [pixel]
    "delta", "epsilon",       # tilt angles of the pixel plane [rad]
    "q3", "q5",               # Legendre coefficients of radial rectification [1]
)
# The seven parameters of the ideal camera, p = (a, b, c, alpha, beta, gamma, L).
IDEAL_PARAMETER_NAMES: tuple[str, ...] = PARAMETER_NAMES[:7]
# Parameters that are set, never estimated (correlated with the angles / a convention).
FIXED_NAMES: tuple[str, ...] = ("R0", "T0", "rho_max")
ALL_NAMES: tuple[str, ...] = PARAMETER_NAMES + FIXED_NAMES

UNITS: dict[str, str] = {
    "a": "m", "b": "m", "c": "m",
    "alpha": "rad", "beta": "rad", "gamma": "rad",
    "L": "pixel", "R0": "pixel", "T0": "pixel",
    "delta": "rad", "epsilon": "rad", "q3": "1", "q5": "1", "rho_max": "1",
}


@dataclass(frozen=True)
class CameraParams:
    """Parameters of one camera; SI units, angles in radians."""

    a: float                 # camera position x [m]
    b: float                 # camera position y [m]
    c: float                 # camera position z [m]
    alpha: float = 0.0       # elevation angle, view line above horizontal > 0 [rad]
    beta: float = 0.0        # roll angle about the view line [rad]
    gamma: float = 0.0       # yaw angle about z, 0 = looking along +y [rad]
    L: float = 400.0         # camera constant L = K d [pixel]
    R0: float = 255.5        # pixel column of the optical axis [pixel]
    T0: float = 255.5        # pixel row of the optical axis [pixel]
    delta: float = 0.0       # tilt of the view line, row direction [rad]
    epsilon: float = 0.0     # tilt of the view line, column direction [rad]
    q3: float = 0.0          # coefficient of Legendre Q3 [1]
    q5: float = 0.0          # coefficient of Legendre Q5 [1]
    rho_max: float = 1.0     # normalising radius of eq. 4.17, ideal-image ratio [1]

    def __post_init__(self) -> None:
        for name in ALL_NAMES:
            value = getattr(self, name)
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise ArgumentError(f"camera parameter {name}={value!r} is not a number") from None
            if not math.isfinite(value):
                raise ArgumentError(f"camera parameter {name}={value!r} is not finite")
            object.__setattr__(self, name, value)
        if self.L <= 0.0:
            raise ArgumentError(f"camera constant L={self.L!r} pixel must be > 0")
        if self.rho_max <= 0.0:
            raise ArgumentError(f"rho_max={self.rho_max!r} must be > 0")

    # -- derived quantities -------------------------------------------------------
    @property
    def position(self) -> np.ndarray:
        """Camera position (a, b, c) [m]."""
        return np.array([self.a, self.b, self.c])

    @property
    def rotation(self) -> np.ndarray:
        """Rotation matrix C of eq. 4.3 (object frame -> camera frame) [1]."""
        return rotation_matrix(self.alpha, self.beta, self.gamma)

    @property
    def is_ideal(self) -> bool:
        """True when the improved-model terms (delta, epsilon, q3, q5) are all zero."""
        return self.delta == 0.0 and self.epsilon == 0.0 and self.q3 == 0.0 and self.q5 == 0.0

    # -- vector / dict round trips ------------------------------------------------
    def to_vector(self, names: Sequence[str] = PARAMETER_NAMES) -> np.ndarray:
        """Parameters ``names`` as a float vector (units as in :data:`UNITS`)."""
        _check_names(names)
        return np.array([getattr(self, n) for n in names], dtype=float)

    @classmethod
    def from_vector(
        cls,
        vector: Iterable[float],
        names: Sequence[str] = PARAMETER_NAMES,
        base: "CameraParams | None" = None,
    ) -> "CameraParams":
        """Build from a vector; parameters not in ``names`` come from ``base``."""
        _check_names(names)
        values = [float(v) for v in vector]
        if len(values) != len(names):
            raise ArgumentError(f"vector has {len(values)} entries but {len(names)} names were given")
        changes = dict(zip(names, values))
        if base is None:
            missing = [n for n in ("a", "b", "c") if n not in changes]
            if missing:
                raise ArgumentError(f"from_vector without base needs {missing}")
            return cls(**changes)
        return dataclasses.replace(base, **changes)

    def to_dict(self) -> dict[str, float]:
        """Plain ``{name: float}`` dict (TOML friendly; units in :data:`UNITS`)."""
        return {n: float(getattr(self, n)) for n in ALL_NAMES}

    @classmethod
    def from_dict(cls, data: Mapping[str, object]) -> "CameraParams":
        """Inverse of :meth:`to_dict`; unknown keys are an error, missing keys default."""
        unknown = sorted(set(data) - set(ALL_NAMES))
        if unknown:
            raise ArgumentError(f"unknown camera parameter(s) {unknown}; known: {list(ALL_NAMES)}")
        for key in ("a", "b", "c"):
            if key not in data:
                raise ArgumentError(f"camera parameter {key!r} (position [m]) is missing")
        return cls(**{k: data[k] for k in data})  # type: ignore[arg-type]


def _check_names(names: Sequence[str]) -> None:
    bad = [n for n in names if n not in ALL_NAMES]
    if bad:
        raise ArgumentError(f"unknown camera parameter name(s) {bad}")
    if len(set(names)) != len(names):
        raise ArgumentError(f"duplicate camera parameter names in {list(names)}")


# ----------------------------------------------------------------------------------
# Rotation and projection (ideal camera)
# ----------------------------------------------------------------------------------
def rotation_matrix(alpha, beta, gamma) -> np.ndarray:
    """Matrix C of eq. 4.3 for elevation alpha, roll beta, yaw gamma [rad].

    ``C = Rbeta @ Ralpha @ Rgamma``: yaw about z first, then elevation about the new
    x axis, finally roll about the view line.  Arrays broadcast; result shape ``(..., 3, 3)``.
    """
    alpha, beta, gamma = np.broadcast_arrays(
        np.asarray(alpha, float), np.asarray(beta, float), np.asarray(gamma, float)
    )
    ca, sa = np.cos(alpha), np.sin(alpha)
    cb, sb = np.cos(beta), np.sin(beta)
    cg, sg = np.cos(gamma), np.sin(gamma)
    C = np.empty(alpha.shape + (3, 3))
    C[..., 0, 0] = cb * cg - sa * sb * sg
    C[..., 0, 1] = cb * sg + sa * sb * cg
    C[..., 0, 2] = -ca * sb
    C[..., 1, 0] = -ca * sg
    C[..., 1, 1] = ca * cg
    C[..., 1, 2] = sa
    C[..., 2, 0] = sb * cg + sa * cb * sg
    C[..., 2, 1] = sb * sg - sa * cb * cg
    C[..., 2, 2] = ca * cb
    return C


def camera_coordinates(cam: CameraParams, x) -> np.ndarray:
    """Camera-frame coordinates ``(u, v, w) = C (x - a)`` [m] of points ``x`` (..., 3) [m]."""
    x = np.asarray(x, float)
    return (x - cam.position) @ cam.rotation.T


def project_ideal(cam: CameraParams, x) -> np.ndarray:
    """Ideal image coordinates ``(r/d, t/d) = (u/v, w/v)`` [1], shape (..., 2).

    Points on or behind the camera (``v <= 0``) give NaN.
    """
    uvw = camera_coordinates(cam, x)
    v = uvw[..., 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.stack([uvw[..., 0] / v, uvw[..., 2] / v], axis=-1)
    out[v <= 0.0] = np.nan
    return out


def project(cam: CameraParams, x) -> np.ndarray:
    """Pixel coordinates ``(R, T)`` [pixel] of object points ``x`` (..., 3) [m].

    Uses the improved model when any of delta, epsilon, q3, q5 is non-zero.
    """
    ideal = project_ideal(cam, x)
    return ideal_to_pixel(cam, ideal)


def homogeneous_matrix(ideal) -> np.ndarray:
    """Matrix A of eq. 4.5 for ideal image coordinates ``(r/d, t/d)`` (..., 2) -> (..., 2, 3)."""
    ideal = np.asarray(ideal, float)
    A = np.zeros(ideal.shape[:-1] + (2, 3))
    A[..., 0, 0] = -1.0
    A[..., 0, 1] = ideal[..., 0]
    A[..., 1, 1] = ideal[..., 1]
    A[..., 1, 2] = -1.0
    return A


# ----------------------------------------------------------------------------------
# Improved model: Legendre rectification and tilted pixel plane
# ----------------------------------------------------------------------------------
def legendre_q3(rho):
    """Legendre polynomial Q3(rho) = (5 rho^3 - 3 rho)/2 (eq. 4.18) [1]."""
    rho = np.asarray(rho, float)
    return 0.5 * (5.0 * rho**3 - 3.0 * rho)


def legendre_q5(rho):
    """Legendre polynomial Q5(rho) = (63 rho^5 - 70 rho^3 + 15 rho)/8 (eq. 4.18) [1]."""
    rho = np.asarray(rho, float)
    return (63.0 * rho**5 - 70.0 * rho**3 + 15.0 * rho) / 8.0


def radial_factor(rho, q3, q5):
    """Kp = 1 + q3 Q3(rho)/rho + q5 Q5(rho)/rho (eq. 4.19), regular at rho = 0 [1]."""
    r2 = np.asarray(rho, float) ** 2
    return 1.0 + q3 * 0.5 * (5.0 * r2 - 3.0) + q5 * (63.0 * r2 * r2 - 70.0 * r2 + 15.0) / 8.0


def _radial_gain_derivative(rho, q3, q5):
    """d(rho Kp)/d rho = 1 + q3 Q3'(rho) + q5 Q5'(rho) [1]."""
    r2 = np.asarray(rho, float) ** 2
    return 1.0 + q3 * 0.5 * (15.0 * r2 - 3.0) + q5 * (315.0 * r2 * r2 - 210.0 * r2 + 15.0) / 8.0


def pixel_to_ideal_arrays(R, T, R0, T0, L, delta, epsilon, q3, q5, rho_max):
    """Eq. 4.15-4.23 on plain arrays (all arguments broadcast).

    ``R, T`` [pixel] -> ideal image coordinates ``(r/d, t/d)`` [1] as a tuple.
    """
    f1 = (R - R0) / L                       # eq. 4.15 [1]
    h1 = (T - T0) / L
    f2 = f1 - epsilon                       # eq. 4.16 [1]
    h2 = h1 + delta
    rho = np.sqrt(f2 * f2 + h2 * h2) / rho_max   # eq. 4.17 [1]
    kp = radial_factor(rho, q3, q5)         # eq. 4.18-4.19 [1]
    f4 = kp * f2 + epsilon                  # eq. 4.20-4.21 [1]
    h4 = kp * h2 - delta
    den = 1.0 + f4 * epsilon - h4 * delta   # eq. 4.22-4.23 [1]
    return f4 / den, h4 / den


def pixel_to_ideal(cam: CameraParams, pixels) -> np.ndarray:
    """Measured pixels ``(R, T)`` (..., 2) [pixel] -> ideal ``(r/d, t/d)`` (..., 2) [1]."""
    pixels = np.asarray(pixels, float)
    rd, td = pixel_to_ideal_arrays(
        pixels[..., 0], pixels[..., 1], cam.R0, cam.T0, cam.L,
        cam.delta, cam.epsilon, cam.q3, cam.q5, cam.rho_max,
    )
    return np.stack([rd, td], axis=-1)


def ideal_to_pixel_arrays(rd, td, R0, T0, L, delta, epsilon, q3, q5, rho_max,
                          iterations: int = 30):
    """Inverse of :func:`pixel_to_ideal_arrays`: ``(r/d, t/d)`` [1] -> ``(R, T)`` [pixel].

    Eq. 4.22-4.23 invert in closed form (``den = 1/(1 - (r/d) eps + (t/d) delta)``);
    the radial step ``rho3 = rho Kp(rho)`` is solved by Newton's method, starting at
    ``rho = rho3``.  Requires ``rho Kp(rho)`` to be increasing over the field of view
    (small q3, q5, rho <~ 1); points where Newton does not converge, or where
    ``rho Kp`` is not increasing between 0 and the root, give NaN.
    """
    rd, td = np.broadcast_arrays(np.asarray(rd, float), np.asarray(td, float))
    den = 1.0 / (1.0 - rd * epsilon + td * delta)
    f4 = rd * den
    h4 = td * den
    f3 = f4 - epsilon
    h3 = h4 + delta
    rho3 = np.sqrt(f3 * f3 + h3 * h3) / rho_max
    if np.all(np.asarray(q3) == 0.0) and np.all(np.asarray(q5) == 0.0):
        kp = np.ones_like(rho3)
    else:
        rho = rho3.copy()
        for _ in range(iterations):
            g = rho * radial_factor(rho, q3, q5) - rho3
            step = g / _radial_gain_derivative(rho, q3, q5)
            rho = rho - step
            if np.all(~np.isfinite(step) | (np.abs(step) <= 1e-15 * (1.0 + np.abs(rho)))):
                break
        residual = np.abs(rho * radial_factor(rho, q3, q5) - rho3)
        # unique root only where rho Kp(rho) increases on [0, rho]: check 16 points
        frac = np.linspace(0.0, 1.0, 16).reshape((16,) + (1,) * np.ndim(rho))
        monotone = np.all(_radial_gain_derivative(frac * rho, q3, q5) > 0.0, axis=0)
        kp = radial_factor(rho, q3, q5)
        kp = np.where((residual <= 1e-12 * (1.0 + rho3)) & monotone & (rho >= 0.0), kp, np.nan)
    f2 = f3 / kp
    h2 = h3 / kp
    f1 = f2 + epsilon
    h1 = h2 - delta
    return R0 + L * f1, T0 + L * h1


def ideal_to_pixel(cam: CameraParams, ideal) -> np.ndarray:
    """Ideal ``(r/d, t/d)`` (..., 2) [1] -> pixels ``(R, T)`` (..., 2) [pixel]."""
    ideal = np.asarray(ideal, float)
    R, T = ideal_to_pixel_arrays(
        ideal[..., 0], ideal[..., 1], cam.R0, cam.T0, cam.L,
        cam.delta, cam.epsilon, cam.q3, cam.q5, cam.rho_max,
    )
    return np.stack([R, T], axis=-1)


# ----------------------------------------------------------------------------------
# Convenience
# ----------------------------------------------------------------------------------
def look_at(position, target, roll: float = 0.0, **kwargs) -> CameraParams:
    """Camera at ``position`` [m] whose view line passes through ``target`` [m].

    ``roll`` is beta [rad]; other keyword arguments (``L``, ``R0``, ...) are passed on.
    From the second row of C, the view direction is
    ``(-cos(alpha) sin(gamma), cos(alpha) cos(gamma), sin(alpha))``.
    """
    p = np.asarray(position, float)
    d = np.asarray(target, float) - p
    horizontal = math.hypot(d[0], d[1])
    if horizontal == 0.0:
        raise ArgumentError("look_at: target straight above/below the camera; yaw undefined")
    gamma = math.atan2(-d[0], d[1])
    alpha = math.atan2(d[2], horizontal)
    return CameraParams(a=p[0], b=p[1], c=p[2], alpha=alpha, beta=roll, gamma=gamma, **kwargs)
