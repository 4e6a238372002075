"""Stops planned from the servos' predicted physical state: over many random
stops and e-stops, in the simulator whose drives do not clip acceleration,
no axis passes the point where it comes to rest by more than 1 % of its
range and none accelerates beyond its limit (docs/architecture.md, Stops).
'stop': the engine's stop ramp (stop_motion) with the nodes following;
'estop': the same with an ESTOP to every node, whose quick stop
(ServoModel.brake) then moves the figure."""
from dataclasses import replace

import numpy as np
import pytest

from marionette import protocol
from marionette.config import load_config
from marionette.engine import Engine
from marionette.show import Show
from marionette.sim.figure import SimFigure

OVERSHOOT = 0.01        # of the axis's range
ACCEL_TOL = 1.02        # peak physical acceleration / limit allowed (rounding, whole counts)
SETTLE = 75             # ticks after the stop until the figure is judged at rest


def figure():
    """The bundled figure's axes (their limits and behaviour models), all on
    one node so that the simulation runs fast enough for many cases."""
    config = load_config(None)
    return replace(config, axes=tuple(replace(a, node=1, channel=j) for j, a in enumerate(config.axes)))


def random_show(config, rng, ticks):
    """A random dance over much of each axis's range at up to its top speed
    and acceleration (sums of sinusoids), starting at rest at home, where the
    simulated nodes start."""
    t = np.arange(ticks) * config.tick_period
    fade = np.sin(np.pi / 2 * np.clip(t / 1.5, 0, 1)) ** 2                 # 1.5 s in from rest
    out = np.empty((len(config.axes), ticks))
    for j, a in enumerate(config.axes):
        mid, half = (a.min + a.max) / 2, (a.max - a.min) / 2
        x = np.zeros(ticks)
        for _ in range(3):
            f = rng.uniform(0.1, 1.2)                                       # [Hz]
            amp = min(half, a.max_speed / (2 * np.pi * f), a.max_accel / (2 * np.pi * f) ** 2)
            x += rng.uniform(0.2, 0.6) * amp * np.sin(2 * np.pi * f * t + rng.uniform(0, 6.3))
        margin = 0.05 * (a.max - a.min)                                     # taught inside the limits
        out[j] = np.clip(a.home + fade * (mid - a.home + x), a.min + margin, a.max - margin)
    return Show(axis_names=config.axis_names, units=[a.unit for a in config.axes],
                positions=out, loudness=np.zeros(ticks), tick_period=config.tick_period)


def stop_run(config, show, stop_tick, kind, seed):
    """Plays show into a SimFigure without acceleration clipping on a
    virtual clock; at stop_tick stop_motion() (kind 'stop') or e-stop
    (the engine's stop and an ESTOP to every node, which arrives with the
    tick's setpoints). Returns (positions per tick after the stop, the
    figure's peak physical acceleration per axis)."""
    T = config.tick_period
    sim = SimFigure(config, clip_accel=False)
    sim.advance_to(0.0)
    x = []
    with Engine(config, show) as engine:
        for k in range(stop_tick + SETTLE):
            if k == stop_tick:
                engine.stop_motion()
                sim.advance_to(k * T)
                peak_before = sim.peak_accel()
            engine.step(1)
            cmd = engine.snapshot().commands.values()
            entries = [(a.node, a.channel, int(round(a.offset + a.scale * c)))
                       for a, c in zip(config.axes, cmd)]
            sim.handle(protocol.Sync(k), k * T)
            if k == stop_tick and kind == "estop":
                sim.handle(protocol.Estop(protocol.BROADCAST), k * T)
            sim.handle(protocol.Setpoints(k, entries), k * T)
            if k >= stop_tick:
                x.append(sim.positions())
    sim.advance_to((stop_tick + SETTLE) * T)
    return np.array(x), np.maximum(peak_before, sim.peak_accel()), peak_before


def measure(kind, cases, seed):
    config = figure()
    span = np.array([a.max - a.min for a in config.axes])
    limit = np.array([a.max_accel for a in config.axes])
    rng = np.random.default_rng(seed)
    over, accel = [], []
    for case in range(cases):
        show = random_show(config, rng, 160 + SETTLE)
        x, peak, _ = stop_run(config, show, int(rng.integers(60, 160)), kind, seed)
        rest = x[-1]
        direction = np.sign(rest - x[0])
        over.append(np.max(direction * (x - rest), axis=0).clip(0) / span)
        accel.append(peak / limit)
    return np.array(over), np.array(accel)


@pytest.mark.parametrize("kind, cases, seed", [("stop", 40, 17), ("estop", 100, 18)])
def test_stops_come_to_rest_within_one_percent_and_the_acceleration_limit(kind, cases, seed):
    over, accel = measure(kind, cases, seed)
    assert over.max() <= OVERSHOOT, (np.median(over.max(axis=1)), over.max(axis=0))
    assert np.all(accel <= ACCEL_TOL), (np.median(accel.max(axis=1)), accel.max(axis=0))
