"""Synthetic ground truth for the teach-in pipeline (tests, sample recordings).

A known, smooth dance of the rucksack is observed by known cameras exactly as the real
system does it: every 20 ms field one LED flashes, in the sequence 1, 2, 3, 4; its
position at that instant is projected into each camera, pixel noise is added, the
result is rounded to integer pixels (the tracker reports the brightest pixel), and
detections are lost at random, in bursts (an LED shaded by the body for a while) and
outside the image.  Everything is deterministic given the seed
(``numpy.random.default_rng(seed)``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .camera import CameraParams, camera_coordinates, look_at, project
from .recording import Recording
from .rucksack import FIELD_PERIOD, led_positions

IMAGE_SIZE = (512, 512)        # sensor columns, rows [pixel]


@dataclass
class Dance:
    """Known rucksack motion: sums of sinusoids plus a steady yaw turn.

    Every coordinate ``q_k(t) = offset_k + rate_k t + sum_i A_ki sin(2 pi f_ki t + p_ki)``
    with ``q = (x0, y0, z0 [m], phi, theta, psi [rad])``; A [m or rad], f [Hz], p [rad],
    rate [unit/s] (non-zero only for psi).
    """

    offset: np.ndarray                      # (6,)
    rate: np.ndarray                        # (6,)
    amplitude: np.ndarray                   # (6, n_terms)
    frequency: np.ndarray                   # (6, n_terms) [Hz]
    phase: np.ndarray                       # (6, n_terms) [rad]

    def pose(self, t) -> np.ndarray:
        """Poses (K, 6) at times ``t`` (K,) [s]."""
        t = np.atleast_1d(np.asarray(t, float))
        arg = 2.0 * np.pi * self.frequency[None] * t[:, None, None] + self.phase[None]
        return self.offset + self.rate * t[:, None] + np.sum(self.amplitude[None] * np.sin(arg), axis=-1)

    def velocity(self, t) -> np.ndarray:
        """Time derivative of :meth:`pose` (K, 6) [m/s, rad/s]."""
        t = np.atleast_1d(np.asarray(t, float))
        w = 2.0 * np.pi * self.frequency[None]
        arg = w * t[:, None, None] + self.phase[None]
        return self.rate + np.sum(self.amplitude[None] * w * np.cos(arg), axis=-1)


def make_dance(
    rng: np.random.Generator,
    area_half: float = 2.0,
    z_mean: float = 1.3,
    max_tilt: float = np.radians(6.0),
    turn_period: float = 8.0,
    n_terms: int = 3,
    max_frequency: float = 0.4,
) -> Dance:
    """Random smooth dance inside a square of half side ``area_half`` [m] (4 m x 4 m).

    x0, y0 stay within 85 % of ``area_half``; z0 varies +-0.15 m around ``z_mean`` [m];
    roll and pitch stay within ``max_tilt`` [rad]; yaw turns fully once per
    ``turn_period`` [s] (random direction) with a small wobble.  Frequencies up to
    ``max_frequency`` [Hz] (x, y) and twice that (z, tilt, yaw wobble).
    """
    amplitude = np.zeros((6, n_terms))
    frequency = rng.uniform(0.05, max_frequency, (6, n_terms))
    frequency[2:] *= 2.0
    phase = rng.uniform(0.0, 2.0 * np.pi, (6, n_terms))
    limits = np.array([0.85 * area_half, 0.85 * area_half, 0.15, max_tilt, max_tilt, 0.3])
    for k in range(6):
        share = rng.uniform(0.2, 1.0, n_terms)
        amplitude[k] = limits[k] * share / share.sum()
    offset = np.array([0.0, 0.0, z_mean, 0.0, 0.0, rng.uniform(-np.pi, np.pi)])
    rate = np.zeros(6)
    rate[5] = rng.choice([-1.0, 1.0]) * 2.0 * np.pi / turn_period
    return Dance(offset, rate, amplitude, frequency, phase)


def default_cameras() -> list[CameraParams]:
    """Two ideal cameras 3 m above the floor, in front of the 4 m x 4 m area, looking
    at its centre 1.2 m high (small elevation, as in the paper) [m, rad, pixel]."""
    target = (0.0, 0.0, 1.2)
    return [
        look_at((-5.0, -4.0, 3.0), target, roll=0.01, L=420.0),
        look_at((5.0, -4.0, 3.0), target, roll=-0.015, L=430.0),
    ]


def observe(cameras, points, rng, noise_px=0.5, quantize=True, image_size=IMAGE_SIZE):
    """Pixels (K, N, 2) of points (N, 3) [m] with Gaussian noise ``noise_px`` [pixel],
    optional rounding to integers; NaN when behind the camera or outside the image."""
    points = np.asarray(points, float)
    out = np.full((len(cameras), points.shape[0], 2), np.nan)
    for k, cam in enumerate(cameras):
        pix = project(cam, points)
        pix = pix + rng.normal(0.0, noise_px, pix.shape)
        if quantize:
            pix = np.round(pix)
        inside = (
            (camera_coordinates(cam, points)[:, 1] > 0.0)
            & (pix[:, 0] >= 0) & (pix[:, 0] <= image_size[0] - 1)
            & (pix[:, 1] >= 0) & (pix[:, 1] <= image_size[1] - 1)
        )
        out[k, inside] = pix[inside]
    return out


@dataclass
class SyntheticRecording:
    """A synthetic recording and the truth behind it."""

    recording: Recording            # the detections, as a tracker would deliver them
    cameras: list[CameraParams]     # the true cameras
    dance: Dance                    # the true motion
    b: float                        # rucksack half side [m]
    field_times: np.ndarray         # (F,) time of every field [s]
    field_leds: np.ndarray          # (F,) LED flashed in that field 1..4
    field_points: np.ndarray        # (F, 3) true position of that LED [m]
    dropped: np.ndarray = field(repr=False, default=None)  # (K, F) bool: detection missing


def synthetic_recording(
    seed: int,
    duration_s: float = 20.0,
    *,
    cameras: list[CameraParams] | None = None,
    b: float = 0.2,
    noise_px: float = 0.5,
    quantize: bool = True,
    dropout: float = 0.01,
    shade_rate: float = 0.1,
    shade_duration: tuple[float, float] = (0.1, 0.4),
    t0: float = 0.0,
    dance: Dance | None = None,
    image_size: tuple[int, int] = IMAGE_SIZE,
) -> SyntheticRecording:
    """Generate a recording of ``duration_s`` [s] starting at ``t0`` [s] with LED1.

    ``b`` rucksack half side [m]; ``noise_px`` Gaussian pixel noise [pixel];
    ``dropout`` probability that a single detection is lost [1]; ``shade_rate`` mean
    number of shading events per second [1/s], each hiding one random LED from all
    cameras for a duration uniform in ``shade_duration`` [s].
    """
    rng = np.random.default_rng(seed)
    cameras = default_cameras() if cameras is None else list(cameras)
    dance = make_dance(rng) if dance is None else dance
    n_fields = int(round(duration_s / FIELD_PERIOD))
    k = np.arange(n_fields)
    times = np.round(t0 + k * FIELD_PERIOD, 9)
    leds = k % 4 + 1
    all_leds = led_positions(dance.pose(times), b)               # (F, 4, 3) [m]
    points = all_leds[k, leds - 1]                               # (F, 3) [m]
    pix = observe(cameras, points, rng, noise_px, quantize, image_size)
    dropped = rng.random((len(cameras), n_fields)) < dropout
    n_events = rng.poisson(shade_rate * duration_s)
    for _ in range(n_events):
        start = rng.uniform(t0, t0 + duration_s)
        length = rng.uniform(*shade_duration)
        led = rng.integers(1, 5)
        dropped[:, (times >= start) & (times < start + length) & (leds == led)] = True
    dropped |= ~np.all(np.isfinite(pix), axis=-1)
    rows_t, rows_c, rows_l, rows_R, rows_T = [], [], [], [], []
    for f in range(n_fields):
        for c in range(len(cameras)):
            if not dropped[c, f]:
                rows_t.append(times[f])
                rows_c.append(c)
                rows_l.append(leds[f])
                rows_R.append(pix[c, f, 0])
                rows_T.append(pix[c, f, 1])
    rec = Recording(np.array(rows_t), np.array(rows_c, int), np.array(rows_l, int),
                    np.array(rows_R), np.array(rows_T))
    return SyntheticRecording(rec, cameras, dance, b, times, leds, points, dropped)


def synthetic_markers(
    seed: int,
    camera: CameraParams,
    n: int = 8,
    noise_px: float = 0.5,
    low=(-2.0, -2.0, 0.0),
    high=(2.0, 2.0, 2.5),
    image_size: tuple[int, int] = IMAGE_SIZE,
):
    """``n`` calibration markers uniformly in the box ``low``..``high`` [m] that the
    camera sees, and their noisy (unrounded) pixels.  Returns ``(X (n, 3), pixels (n, 2))``."""
    rng = np.random.default_rng(seed)
    found: list[np.ndarray] = []
    while len(found) < n:
        X = rng.uniform(low, high, (4 * n, 3))
        pix = observe([camera], X, rng, noise_px, quantize=False, image_size=image_size)[0]
        found.extend(X[np.all(np.isfinite(pix), axis=1)])
    X = np.array(found[:n])
    pixels = project(camera, X) + rng.normal(0.0, noise_px, (n, 2))
    return X, pixels
