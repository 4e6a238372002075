"""Stops in the simulator whose drives do not clip acceleration (the bare
behaviour model: dead time and first-order lag), over many random cases.

'stop': the engine's stop ramp (stop_motion: also the pause, Ctrl-C, the
fault reactions and the end's hold), commanded mid-motion, in a random
dance or in a move at top speed. Its stop point is where the drive itself
comes to rest braking at its acceleration limit from its physical state
when the ramp's first command takes effect (the setpoints inside its dead
time and lag played out): no axis may pass it by more than 1 % of its
range, nor stop short of it by more, nor accelerate beyond its limit at
any instant by more than sending whole counts can add (rounding_accel;
docs/architecture.md, Stops).
'quick stop': the nodes' own stop (ServoModel.brake), on an ESTOP or a
watchdog trip, mid-motion: the same stop point, from where each drive is
when the node brakes, the same 1 %, and the same acceleration bound: the
braking itself adds nothing to the commands' rounding (SPEC.md 6, Quick
stop)."""
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace

import numpy as np
import pytest

from marionette import protocol
from marionette.config import load_config
from marionette.engine import Engine
from marionette.show import Show
from marionette.sim.figure import SimFigure
from marionette.sim.servo import FINE_STEP

OVERSHOOT = 0.01        # of the axis's range
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


@pytest.fixture(scope="module")
def run_all():
    """run_all(f, cases): [f(case) for case in cases], in worker processes
    (one per CPU, at most 4). Each case is drawn in full, in order, from the
    test's seed before any runs, and runs on its own simulator and engine,
    so the results are those of running them one after another."""
    workers = min(4, len(os.sched_getaffinity(0)))
    if workers < 2:
        yield lambda f, cases: [f(case) for case in cases]
        return
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        yield lambda f, cases: list(pool.map(f, cases))


def drive(config, engine, sim, ticks, on_tick, at_step=None, silent_from=None):
    """Runs the engine in step mode into sim (all on one virtual clock) for
    ticks ticks, calling on_tick(k) before tick k and, with at_step = (n,
    act), act() once the drives are at fine step n; from tick silent_from on
    the host sends nothing. Returns the drives' positions at every fine step
    from model time 0 [unit] (steps x axes). The drives run a tick (or up
    to step n) at a time, and the positions of its fine steps are read from
    the model's ring of its last two ticks' (ServoModel._past, where its
    peak_accel is measured): the same steps as advancing one at a time."""
    T = config.tick_period
    model = next(iter(sim.nodes.values())).model
    per_tick = model.sample_steps
    cols = [j for _, j in sim._where]                                   # all on one node
    back = np.arange(per_tick - 1, -1, -1)                              # [fine steps]
    fine = [sim.positions()[None]]
    for k in range(ticks):
        if k:                                                           # the drives up to tick k
            end = k * per_tick                                          # [fine steps]
            if at_step is not None and end - per_tick < at_step[0] <= end:
                sim.advance_to(at_step[0] * model.step)
                at_step[1]()
            sim.advance_to(end * model.step)
            assert model._steps == end
            fine.append(model._past[(end - back) % len(model._past)][:, cols])
        on_tick(k)
        engine.step(1)
        if silent_from is not None and k >= silent_from:
            continue
        cmd = engine.snapshot().commands.values()
        entries = [(a.node, a.channel, int(round(a.offset + a.scale * c))) for a, c in zip(config.axes, cmd)]
        sim.handle(protocol.Sync(k), k * T)
        sim.handle(protocol.Setpoints(k, entries), k * T)
    return np.concatenate(fine)


def physical_stop(config, sim, fine, stop_tick):
    """Per axis: (where the drive is when the stop's first command acts, its
    velocity over the tick before [unit/s], where braking at its limit from
    there ends [unit]), from the simulated drives themselves."""
    model = next(iter(sim.nodes.values())).model
    at = stop_tick * model.sample_steps + model.delay_steps              # [fine steps], per axis
    cols = np.arange(len(config.axes))
    y = fine[at, cols]
    v = (y - fine[at - model.sample_steps, cols]) / config.tick_period
    return at, v, braking_point(config, y, v)


def rounding_accel(config, step=FINE_STEP):
    """Per axis: the most that sending whole counts (each setpoint off by at
    most half a count, 1 / (2 scale) [unit]) can add to the simulator's
    acceleration measure [unit/s^2]. The lag is linear in its input, so the
    measure at a phase of the tick is a weighted sum of the setpoints held
    before it; the bound is half a count times the sum of the weights'
    magnitudes, at the worst of the tick's fine-step phases. (Where the
    drive runs at top speed, a setpoint moves it less, not more.)"""
    T = config.tick_period
    out = []
    for a in config.axes:
        keep = np.exp(-T / a.time_constant)                                 # of a gap, over a tick
        worst = 0.0
        for n in range(1, int(round(T / step)) + 1):                        # phase: n fine steps in
            part = np.exp(-n * step / a.time_constant)                      # ... of a gap, over those
            # position n steps into tick k: weights of the setpoints of ticks k, k-1, ...
            w = np.concatenate([[1 - part], part * (1 - keep) * keep ** np.arange(60)])
            h = w - 2 * np.concatenate([[0], w[:-1]]) + np.concatenate([[0, 0], w[:-2]])
            worst = max(worst, np.abs(h).sum())
        out.append(worst / (2 * a.scale) / T ** 2)
    return np.array(out)


def braking_point(config, y, v):
    """Per axis: where a drive at y [unit] moving at v [unit/s] comes to
    rest braking at its limit, inside its position limits [unit]."""
    amax = np.array([a.max_accel for a in config.axes])
    return np.clip(y + v * np.abs(v) / (2 * amax), [a.min for a in config.axes], [a.max for a in config.axes])


def stop_figures(config, sim, after, v, stop):
    """Per axis, from the fine positions from the stop on (after), the
    velocity when it acted [unit/s] and its stop point [unit]: (how far past
    the stop point it went, |rest - stop point|, both / the range; the peak
    physical acceleration over the run / the limit; |v| / the top speed)."""
    direction = np.where(v != 0, np.sign(v), 1.0)
    over = np.max(direction * (after - stop), axis=0).clip(0)
    rest = np.abs(after[-1] - stop)
    span = np.array([a.max - a.min for a in config.axes])
    limit = np.array([a.max_accel for a in config.axes])
    vmax = np.array([a.max_speed for a in config.axes])
    return over / span, rest / span, sim.peak_accel() / limit, np.abs(v) / vmax


def motion(config, rng, kind):
    """The motion a stop interrupts, drawn: a random dance ('dance'), or a
    move from home to a far random pose ('move', near top speed at the
    stop). Returns (the show, the tick to stop at, the move's pose or None);
    make_engine() makes its engine."""
    if kind == "dance":
        show = random_show(config, rng, 160 + SETTLE)
        stop_tick = int(rng.integers(60, 160))
        pose = None
    else:
        show = random_show(config, rng, 2)
        stop_tick = int(rng.integers(12, 30))
        pose = {a.name: float(rng.choice([a.min, a.max]) * 0.9 + 0.1 * a.home) for a in config.axes}
    return show, stop_tick, pose


def make_engine(config, show, pose):
    """motion()'s engine: (the engine, {tick: request to make before it})."""
    if pose is None:
        return Engine(config, show), {}
    engine = Engine(config, show, start_pose="home")
    return engine, {0: lambda: engine.move_to(pose)}


def stop_case(config, rng, kind):
    """One engine stop mid-motion (motion(): a dance, or a move stopped near
    top speed), drawn; run_stop_case runs it."""
    return config, motion(config, rng, kind)


def run_stop_case(case):
    """stop_case's stop run: its stop_figures."""
    config, (show, stop_tick, pose) = case
    sim = SimFigure(config, clip_accel=False)
    sim.advance_to(0.0)
    engine, request = make_engine(config, show, pose)
    request[stop_tick] = engine.stop_motion
    with engine:
        fine = drive(config, engine, sim, stop_tick + SETTLE, lambda k: request.get(k, lambda: None)())
    at, v, stop = physical_stop(config, sim, fine, stop_tick)
    return stop_figures(config, sim, fine[at.min():], v, stop)


def test_stop_ramps_brake_the_drives_to_their_own_stop_point(run_all):
    """Over 24 random stops of each kind (16 axes each), fixed seed."""
    config = figure()
    rng = np.random.default_rng(19)
    results = run_all(run_stop_case, [stop_case(config, rng, kind) for kind in ("dance", "move") for _ in range(24)])
    over, rest, accel, speed = (np.array(r) for r in zip(*results))
    print(f"stops: {over.size} axis-stops, speed up to {speed.max():.2f} x the top speed "
          f"(median {np.median(speed):.2f}); past the stop point: max {100 * over.max():.3f} % of the range; "
          f"rest off it: max {100 * rest.max():.3f} %; peak acceleration max {accel.max():.3f} x the limit")
    assert np.sum(speed > 0.8) >= 100                   # many stops at high speed
    assert over.max() <= OVERSHOOT, (over.max(axis=0), np.unravel_index(over.argmax(), over.shape))
    assert rest.max() <= OVERSHOOT, rest.max(axis=0)
    amax = np.array([a.max_accel for a in config.axes])
    assert np.all(accel <= 1 + rounding_accel(config) / amax), accel.max(axis=0)


def quick_stop_case(config, rng, kind, trigger):
    """One quick stop of the nodes themselves mid-motion (in a random dance
    or in a move near top speed, as stop_case): an ESTOP to every node at a
    random fine step within a tick ('estop'), or the host going silent with
    a one-tick watchdog ('watchdog': it trips before the last setpoint's
    hold reaches the drives, with setpoints still inside their dead time).
    Its stop point is where the drive itself comes to rest braking at its
    limit from where it is and its velocity over the tick before when the
    node brakes. Returns its stop_figures and, per axis, the peak
    acceleration measure over the positions from the brake on alone / the
    limit (the node's own braking, without the motion before it). This
    draws the case; run_quick_stop_case runs it."""
    per_tick = next(iter(SimFigure(config).nodes.values())).model.sample_steps   # [fine steps]
    show, stop_tick, pose = motion(config, rng, kind)
    if trigger == "estop":
        at = stop_tick * per_tick + int(rng.integers(0, per_tick))           # [fine steps]
    else:
        at = stop_tick * per_tick
    return config, (show, stop_tick, pose), trigger, at


def run_quick_stop_case(case):
    """quick_stop_case's quick stop run: its stop_figures and the peak
    acceleration measure from the brake on / the limit."""
    config, (show, stop_tick, pose), trigger, at = case
    T = config.tick_period
    sim = SimFigure(config, clip_accel=False)
    sim.advance_to(0.0)
    node = next(iter(sim.nodes.values()))
    per_tick, step = node.model.sample_steps, node.model.step                # [fine steps], [s]
    engine, request = make_engine(config, show, pose)
    if trigger == "estop":
        at_step = (at, lambda: sim.handle(protocol.Estop(protocol.BROADCAST), at * step))
        silent_from = None
    else:
        # the last setpoint at stop_tick - 1; then the watchdog shortened to a tick
        request[stop_tick] = lambda: sim.handle(protocol.Config(1, (), 1, round(T * 1e6), 0), stop_tick * T)
        at_step = None
        silent_from = stop_tick
    with engine:
        fine = drive(config, engine, sim, stop_tick + SETTLE, lambda k: request.get(k, lambda: None)(),
                     at_step, silent_from)
    assert node.model.braking.all() and node.counters.watchdog_trips == (trigger == "watchdog"), \
        (trigger, stop_tick, at, node.model.braking, node.counters)
    y = fine[at]
    v = (y - fine[at - per_tick]) / T
    after = fine[at:]
    own = np.abs(after[2 * per_tick:] - 2 * after[per_tick:-per_tick] + after[:-2 * per_tick]).max(axis=0)
    limit = np.array([a.max_accel for a in config.axes])
    return (*stop_figures(config, sim, after, v, braking_point(config, y, v)), own / (T * T) / limit)


def test_quick_stops_brake_the_drives_to_their_own_stop_point(run_all):
    """Over 100 random e-stops and 32 watchdog trips (16 axes each), fixed seed."""
    config = figure()
    rng = np.random.default_rng(18)
    cases = [(kind, trigger) for trigger, n in (("estop", 50), ("watchdog", 16)) for kind in ("dance", "move")
             for _ in range(n)]
    results = run_all(run_quick_stop_case, [quick_stop_case(config, rng, kind, trigger) for kind, trigger in cases])
    over, rest, accel, speed, own = (np.array(r) for r in zip(*results))
    print(f"quick stops: {over.size} axis-stops, speed up to {speed.max():.2f} x the top speed "
          f"(median {np.median(speed):.2f}); past the stop point: max {100 * over.max():.3f} % of the range "
          f"(median of the cases' max {100 * np.median(over.max(axis=1)):.3f} %); "
          f"rest off it: max {100 * rest.max():.3f} %; peak acceleration max {accel.max():.4f} x the limit "
          f"(from the brake on {own.max():.4f})")
    assert np.sum(speed > 0.8) >= 100                   # many stops at high speed
    assert over.max() <= OVERSHOOT, (over.max(axis=0), np.unravel_index(over.argmax(), over.shape))
    assert rest.max() <= OVERSHOOT, rest.max(axis=0)
    # the braking itself keeps to the limit (but for floating point); the
    # windows reaching back before it to the larger of that and the motion
    # before, the engine's counts: the limit and their rounding
    amax = np.array([a.max_accel for a in config.axes])
    assert np.all(own <= 1 + 1e-9), own.max(axis=0)
    assert np.all(accel <= 1 + rounding_accel(config) / amax), accel.max(axis=0)
