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
from marionette.errors import ArgumentError


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
    t_sets, sets = align_to_set_times(points.times, points.leds, points.points, half_side=b)
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


@dataclass
class TeachStages:
    """Every intermediate result of :func:`teach_poses` (for reports and plots).

    Set-rate stages are poses (K, 6) = ``(x0, y0, z0 [m], phi, theta, psi [rad])`` at
    ``set_times``; the tick stage is (N, 6) at ``tick_times = k dt``, k = 0..N-1.
    """

    set_times: np.ndarray      # (K,) common set times [s]
    raw: np.ndarray            # fit of the sets as recorded: NaN where an LED is missing
    complemented: np.ndarray   # fit after complementing one missing LED
    bridged: np.ndarray        # yaw unwrapped, gaps bridged linearly
    lowpass: np.ndarray        # 21-tap FIR
    compressed: np.ndarray     # x0, y0 compressed into the marionette's area
    tick_times: np.ndarray     # (N,) [s]
    resampled: np.ndarray      # (N, 6) on the 20 ms tick
    n_fields: int              # video fields with at least one detection
    n_points: int              # fields whose LED was triangulated
    n_complemented: int        # sets with exactly one LED rebuilt
    n_lost: int                # sets with two or more LEDs missing
    gaps: list[tuple[float, float]]   # (last valid, next valid) set time of each bridged gap [s]


def _gaps(times: np.ndarray, missing: np.ndarray) -> list[tuple[float, float]]:
    """Runs of missing sets as (time before, time after) [s]; ends use the run's own edge."""
    out = []
    k = 0
    n = missing.size
    while k < n:
        if not missing[k]:
            k += 1
            continue
        start = k
        while k < n and missing[k]:
            k += 1
        out.append((float(times[start - 1] if start > 0 else times[start]),
                    float(times[k] if k < n else times[k - 1])))
    return out


def teach_poses(
    rec: Recording,
    cameras: Sequence[CameraParams],
    b: float,
    *,
    nonlinear: bool = False,
    max_residual_px: float = DEFAULT_MAX_RESIDUAL_PX,
    cutoff_hz: float = DEFAULT_CUTOFF,
    compress_x: SoftLimit | None = None,
    compress_y: SoftLimit | None = None,
    max_gap: float | None = None,
    dt: float = TICK,
) -> TeachStages:
    """The whole chain from detections to poses on the show's tick, keeping every stage.

    Show tick k is at recording time ``k dt`` [s] (``time_s`` counts from the start of
    the music); ticks before the first set hold the first pose, times before 0 are
    dropped, the last tick is the last one at or before the last set.
    """
    points = led_points(rec, cameras, max_residual_px=max_residual_px)
    t_sets, sets = align_to_set_times(points.times, points.leds, points.points, half_side=b)
    fit = fit_nonlinear if nonlinear else fit_linear
    raw = fit(sets, b).pose
    filled, n_missing = complement_missing_led(sets)
    complemented = fit(filled, b).pose
    missing = ~np.all(np.isfinite(complemented), axis=1)
    if missing.all():
        raise ArgumentError("no LED set could be reconstructed: every set misses two or more LEDs")
    if t_sets.size < 2:
        raise ArgumentError("the recording holds fewer than two LED sets (160 ms)")
    q = complemented.copy()
    q[:, 5] = unwrap_angle(q[:, 5])
    bridged, _ = bridge_gaps(t_sets, q, max_gap=max_gap)
    lowpass = fir_filter(bridged, design_lowpass(cutoff_hz, 1.0 / SET_PERIOD))
    compressed = lowpass.copy()
    if compress_x is not None:
        compressed[:, 0] = compress_x(compressed[:, 0])
    if compress_y is not None:
        compressed[:, 1] = compress_y(compressed[:, 1])
    if t_sets[-1] < 0:
        raise ArgumentError("every set lies before time 0 (the start of the music)")
    t_tick, q_tick = resample(t_sets, compressed, dt=dt, t_start=0.0)
    n_lead = int(round(t_tick[0] / dt))      # ticks before the first set: hold its pose
    q_tick = np.concatenate([np.repeat(q_tick[:1], n_lead, axis=0), q_tick])
    t_tick = dt * np.arange(q_tick.shape[0])
    return TeachStages(
        set_times=t_sets, raw=raw, complemented=complemented, bridged=bridged,
        lowpass=lowpass, compressed=compressed, tick_times=t_tick, resampled=q_tick,
        n_fields=int(points.times.size), n_points=int(np.sum(np.isfinite(points.points[:, 0]))),
        n_complemented=int(np.sum(n_missing == 1)), n_lost=int(np.sum(n_missing >= 2)),
        gaps=_gaps(t_sets, missing),
    )
