"""Chain of the teach-in steps, from a recording to 50 Hz generalized coordinates.

    recording --triangulate (per field)--> LED points --align to set time-->
    (K, 4, 3) sets @ 12.5 Hz --complement one missing LED--> rucksack fit -->
    q = (x0, y0, z0, phi, theta, psi) --unwrap psi, bridge gaps, FIR low-pass,
    compress x0, y0--> resample to the 20 ms tick

Each step is a function of its own module; this module only wires them together
with explicit parameters (no file or CLI handling).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .camera import CameraParams
from .filters import (
    DEFAULT_CUTOFF,
    TICK,
    SoftLimit,
    bridge_gaps,
    complement_missing_led,
    design_lowpass,
    fir_filter,
    resample,
    unwrap_angle,
)
from .recording import Recording
from .rucksack import SET_PERIOD, RucksackFit, align_to_set_times, fit_linear, fit_nonlinear
from .triangulate import DEFAULT_MAX_RESIDUAL_PX, triangulate


@dataclass
class LedPoints:
    """Triangulated LED of every field."""

    times: np.ndarray        # (F,) field times [s]
    leds: np.ndarray         # (F,) LED number 1..4
    points: np.ndarray       # (F, 3) [m]; NaN if fewer than 2 cameras or residual too large
    residual_px: np.ndarray  # (F,) rms reprojection error [pixel]


def led_points(rec: Recording, cameras: Sequence[CameraParams],
               max_residual_px: float = DEFAULT_MAX_RESIDUAL_PX) -> LedPoints:
    """Triangulate every field of a recording (eq. 4.10-4.14)."""
    times, leds, pixels = rec.fields(n_cameras=len(cameras))
    tri = triangulate(cameras, pixels, max_residual_px=max_residual_px)
    pts = np.where(tri.ok[:, None], tri.points, np.nan)
    return LedPoints(times, leds, pts, tri.residual_px)


@dataclass
class SetCoordinates:
    """Generalized coordinates per LED set (12.5 Hz)."""

    times: np.ndarray        # (K,) common set times [s]
    led_points: np.ndarray   # (K, 4, 3) after complementing [m]
    n_missing: np.ndarray    # (K,) LEDs missing before complementing
    fit: RucksackFit         # pose (K, 6), NaN where >= 2 LEDs were missing


def set_coordinates(points: LedPoints, b: float, nonlinear: bool = False) -> SetCoordinates:
    """Align LED tracks to set times, complement, fit the rucksack (eq. 5.3-5.7)."""
    t_sets, sets = align_to_set_times(points.times, points.leds, points.points)
    filled, n_missing = complement_missing_led(sets)
    fit = fit_nonlinear(filled, b) if nonlinear else fit_linear(filled, b)
    return SetCoordinates(t_sets, filled, n_missing, fit)


def smooth_trajectory(
    times,
    pose,
    *,
    cutoff_hz: float = DEFAULT_CUTOFF,
    compress_x: SoftLimit | None = None,
    compress_y: SoftLimit | None = None,
    dt: float = TICK,
    max_gap: float | None = None,
):
    """Semantic filters on set poses (K, 6) at set times (K,) [s].

    Unwraps psi, bridges NaN gaps (``max_gap`` [s]), low-passes every coordinate with
    the 21-tap FIR (``cutoff_hz`` [Hz] at the set rate), compresses x0, y0 into the
    marionette area and resamples to ``dt`` [s].  Returns ``(t_tick (N,), pose (N, 6))``.
    """
    times = np.asarray(times, float)
    q = np.array(pose, dtype=float, copy=True)
    q[:, 5] = unwrap_angle(q[:, 5])
    q, _ = bridge_gaps(times, q, max_gap=max_gap)
    rate = 1.0 / float(np.median(np.diff(times))) if times.size > 1 else 1.0 / SET_PERIOD
    q = fir_filter(q, design_lowpass(cutoff_hz, rate))
    if compress_x is not None:
        q[:, 0] = compress_x(q[:, 0])
    if compress_y is not None:
        q[:, 1] = compress_y(q[:, 1])
    return resample(times, q, dt=dt)
