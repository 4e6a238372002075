"""Helpers of the hardware-in-the-loop tests (the simulator process and its
fixture `sim` are in tests/conftest.py)."""
import numpy as np

from marionette.show import Show


def dance_from_home(config, seconds: float, seed: int, fraction: float = 0.25) -> Show:
    """A slow random dance that starts and ends at rest at home (where the
    simulated nodes start) and stays well inside every limit."""
    rng = np.random.default_rng(seed)
    n = int(round(seconds / config.tick_period))
    t = np.arange(n) * config.tick_period
    envelope = np.sin(np.pi * t / t[-1]) ** 2                  # 0 at both ends, smooth
    positions = np.empty((len(config.axes), n))
    for j, a in enumerate(config.axes):
        f = rng.uniform(0.3, 0.8)                              # [Hz]
        amp = min(fraction * (a.max - a.min) / 2, 0.3 * a.max_speed / (2 * np.pi * f),
                  0.2 * a.max_accel / (2 * np.pi * f) ** 2)
        room = min(a.home - a.min, a.max - a.home)
        positions[j] = a.home + min(amp, 0.8 * room) * envelope * np.sin(2 * np.pi * f * t)
    return Show(axis_names=config.axis_names, units=[a.unit for a in config.axes],
                positions=positions, loudness=np.zeros(n), tick_period=config.tick_period,
                source=f"dance_from_home seed {seed}")
