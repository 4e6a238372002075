"""The bundled demo show (data/demo_show.csv) and how it is made.

A deterministic synthetic dance for any figure: per axis a few slow sine
components around the middle of its range, scaled so the taught motion
stays within 80 % of the position range and half the axis's top speed and
acceleration; the stored loudness is a 120 bpm beat under a slow swell.
Regenerate with ``python -m marionette.demo``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from marionette.config import FigureConfig, load_config
from marionette.show import Show

DEMO_SHOW = Path(__file__).parent / "data" / "demo_show.csv"
DEMO_SECONDS = 20.0   # [s]
DEMO_SEED = 1996


def make_demo_show(config: FigureConfig, seconds: float = DEMO_SECONDS, seed: int = DEMO_SEED) -> Show:
    rng = np.random.default_rng(seed)
    T = config.tick_period
    t = np.arange(int(round(seconds / T))) * T                     # [s]
    positions = np.empty((len(config.axes), len(t)))
    for j, axis in enumerate(config.axes):
        freqs = rng.uniform(0.1, 0.6, size=3)                      # [Hz]
        phases = rng.uniform(0, 2 * np.pi, size=3)                 # [rad]
        weights = rng.uniform(0.3, 1.0, size=3)
        shape = sum(w * np.sin(2 * np.pi * f * t + ph) for w, f, ph in zip(weights, freqs, phases))
        shape -= shape[0]                                          # start at the middle, ...
        shape *= np.minimum(1.0, t / 2.0)                          # ... easing in over 2 s
        speed = np.max(np.abs(np.gradient(shape, T)))
        accel = np.max(np.abs(np.gradient(np.gradient(shape, T), T)))
        half_range = 0.4 * (axis.max - axis.min)
        gain = min(half_range / np.max(np.abs(shape)), 0.5 * axis.max_speed / speed,
                   0.5 * axis.max_accel / accel)
        positions[j] = 0.5 * (axis.min + axis.max) + gain * shape
    beat = np.maximum(0.0, np.cos(2 * np.pi * 2.0 * t)) ** 8       # 120 bpm
    swell = 0.5 + 0.4 * np.sin(2 * np.pi * t / seconds)
    loudness = swell * (0.3 + 0.7 * beat)
    return Show(axis_names=config.axis_names, units=[a.unit for a in config.axes],
                positions=np.round(positions, 6), loudness=np.round(loudness, 6),
                tick_period=T, source=f"marionette.demo seed {seed}", music="")


if __name__ == "__main__":
    make_demo_show(load_config()).save(DEMO_SHOW)
    print(f"wrote {DEMO_SHOW}")
