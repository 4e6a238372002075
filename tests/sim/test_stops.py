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
from dataclasses import replace

import numpy as np

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


def drive(config, engine, sim, ticks, on_tick, on_step=lambda step: None, silent_from=None):
    """Runs the engine in step mode into sim (all on one virtual clock) for
    ticks ticks, calling on_tick(k) before tick k and on_step(n) once the
    drives are at fine step n; from tick silent_from on the host sends
    nothing. Returns the drives' positions at every fine step from model
    time 0 [unit] (steps x axes)."""
    T = config.tick_period
    model = next(iter(sim.nodes.values())).model
    per_tick = model.sample_steps
    fine = [sim.positions()]
    for k in range(ticks):
        for i in range(1, per_tick + 1 if k else 1):                    # the drives up to tick k
            step = (k - 1) * per_tick + i
            sim.advance_to(step * model.step)
            on_step(step)
            fine.append(sim.positions())
        on_tick(k)
        engine.step(1)
        if silent_from is not None and k >= silent_from:
            continue
        cmd = engine.snapshot().commands.values()
        entries = [(a.node, a.channel, int(round(a.offset + a.scale * c))) for a, c in zip(config.axes, cmd)]
        sim.handle(protocol.Sync(k), k * T)
        sim.handle(protocol.Setpoints(k, entries), k * T)
    return np.array(fine)


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
    """The motion a stop interrupts: a random dance ('dance'), or a move from
    home to a far random pose ('move', near top speed at the stop). Returns
    (the engine, the tick to stop at, {tick: request to make before it})."""
    if kind == "dance":
        show = random_show(config, rng, 160 + SETTLE)
        stop_tick = int(rng.integers(60, 160))
        engine = Engine(config, show)
        request = {}
    else:
        show = random_show(config, rng, 2)
        stop_tick = int(rng.integers(12, 30))
        engine = Engine(config, show, start_pose="home")
        pose = {a.name: float(rng.choice([a.min, a.max]) * 0.9 + 0.1 * a.home) for a in config.axes}
        request = {0: lambda: engine.move_to(pose)}
    return engine, stop_tick, request


def stop_case(config, rng, kind):
    """One engine stop mid-motion (motion(): a dance, or a move stopped near
    top speed); its stop_figures."""
    sim = SimFigure(config, clip_accel=False)
    sim.advance_to(0.0)
    engine, stop_tick, request = motion(config, rng, kind)
    request[stop_tick] = engine.stop_motion
    with engine:
        fine = drive(config, engine, sim, stop_tick + SETTLE, lambda k: request.get(k, lambda: None)())
    at, v, stop = physical_stop(config, sim, fine, stop_tick)
    return stop_figures(config, sim, fine[at.min():], v, stop)


def test_stop_ramps_brake_the_drives_to_their_own_stop_point():
    """Over 24 random stops of each kind (16 axes each), fixed seed."""
    config = figure()
    rng = np.random.default_rng(19)
    results = [stop_case(config, rng, kind) for kind in ("dance", "move") for _ in range(24)]
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
    limit (the node's own braking, without the motion before it)."""
    T = config.tick_period
    sim = SimFigure(config, clip_accel=False)
    sim.advance_to(0.0)
    node = next(iter(sim.nodes.values()))
    per_tick, step = node.model.sample_steps, node.model.step                # [fine steps], [s]
    engine, stop_tick, request = motion(config, rng, kind)
    if trigger == "estop":
        at = stop_tick * per_tick + int(rng.integers(0, per_tick))           # [fine steps]
        on_step = lambda n: sim.handle(protocol.Estop(protocol.BROADCAST), n * step) if n == at else None
        silent_from = None
    else:
        # the last setpoint at stop_tick - 1; then the watchdog shortened to a tick
        at = stop_tick * per_tick
        request[stop_tick] = lambda: sim.handle(protocol.Config(1, (), 1, round(T * 1e6), 0), stop_tick * T)
        on_step = lambda n: None
        silent_from = stop_tick
    with engine:
        fine = drive(config, engine, sim, stop_tick + SETTLE, lambda k: request.get(k, lambda: None)(),
                     on_step, silent_from)
    assert node.model.braking.all() and node.counters.watchdog_trips == (trigger == "watchdog")
    y = fine[at]
    v = (y - fine[at - per_tick]) / T
    after = fine[at:]
    own = np.abs(after[2 * per_tick:] - 2 * after[per_tick:-per_tick] + after[:-2 * per_tick]).max(axis=0)
    limit = np.array([a.max_accel for a in config.axes])
    return (*stop_figures(config, sim, after, v, braking_point(config, y, v)), own / (T * T) / limit)


def test_quick_stops_brake_the_drives_to_their_own_stop_point():
    """Over 100 random e-stops and 32 watchdog trips (16 axes each), fixed seed."""
    config = figure()
    rng = np.random.default_rng(18)
    cases = [(kind, trigger) for trigger, n in (("estop", 50), ("watchdog", 16)) for kind in ("dance", "move")
             for _ in range(n)]
    results = [quick_stop_case(config, rng, kind, trigger) for kind, trigger in cases]
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
