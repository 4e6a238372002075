"""The C tick through its Python API, in step mode."""
import os
import tty

import numpy as np
import pytest
import serial
from hypothesis import given, settings, strategies as st

from marionette import Engine, EngineError, ShowError
from marionette import protocol
from marionette._core import FLAG_BAD_INPUT, FLAG_END, FLAG_LIMITED
from marionette.recorder import read_flight_record

from conftest import make_figure, make_show, smooth_dance


def check_limits(config, commands, start, stopping=None):
    """Every command within position, speed and acceleration limits (1e-9
    relative); stopping: ticks of a stop ramp (FLAG_STOPPING), whose
    acceleration bound acts on the drives' predicted motion instead (checked
    by ext/tests/test_engine.c and tests/sim/test_stops.py)."""
    T = config.tick_period
    x = np.vstack([start, commands])                        # [unit], row per tick
    v = np.diff(x, axis=0) / T                              # [unit/s]
    a = np.diff(np.vstack([np.zeros(len(start)), v]), axis=0) / T
    if stopping is not None:
        a[np.asarray(stopping, dtype=bool)] = 0.0
    for j, axis in enumerate(config.axes):
        tol = 1e-9 * max(1.0, abs(axis.min), abs(axis.max))
        assert np.all(x[:, j] >= axis.min - tol) and np.all(x[:, j] <= axis.max + tol), axis.name
        assert np.max(np.abs(v[:, j])) <= axis.max_speed * (1 + 1e-9) + 1e-9, axis.name
        assert np.max(np.abs(a[:, j])) <= axis.max_accel * (1 + 1e-9) + 1e-9 / T, axis.name


axis_model = st.fixed_dictionaries(dict(
    span=st.floats(0.05, 5.0), max_speed=st.floats(0.01, 5.0), max_accel=st.floats(0.05, 50.0),
    dead_time=st.floats(0.0, 0.3), time_constant=st.floats(0.0, 0.5)))


@settings(derandomize=True, max_examples=150, deadline=None)
@given(models=st.lists(axis_model, min_size=1, max_size=4), ticks=st.integers(2, 200),
       rate=st.floats(0.0, 4.0), lead=st.sampled_from(["dead_time_lag", "mean_delay", "none"]),
       interpolation=st.sampled_from(["cubic", "linear"]), seed=st.integers(0, 2**32 - 1))
def test_commands_never_exceed_limits(models, ticks, rate, lead, interpolation, seed):
    from marionette.config import config_from_dict
    doc = {"figure": {"tick_period": 0.02}, "axis": [
        dict(name=f"a{j}", node=1, channel=j, unit="m", min=0.0, max=m["span"], home=0.0,
             max_speed=m["max_speed"], max_accel=m["max_accel"], dead_time=m["dead_time"],
             time_constant=m["time_constant"], scale=1000.0) for j, m in enumerate(models)]}
    config = config_from_dict(doc)
    rng = np.random.default_rng(seed)
    spans = np.array([[m["span"]] for m in models])
    positions = rng.uniform(0, 1, (len(models), ticks)) * spans   # jumpy: limits must act
    with Engine(config, make_show(config, positions), lead=lead, interpolation=interpolation,
                rate=rate, record=True) as engine:
        engine.step(ticks + 20)
        records = engine.records()
    assert len(records) == ticks + 20
    check_limits(config, records["command"], positions[:, 0])


def test_step_mode_is_bit_reproducible(rng):
    config = make_figure(5)
    show = make_show(config, smooth_dance(config, 500, rng), rng.uniform(0, 1, 500))
    runs = []
    for _ in range(2):
        with Engine(config, show, record=True) as engine:
            engine.step(123)
            engine.set_rate(1.37)
            engine.step(200)
            engine.seek(42.5)
            engine.push_loudness(0.25)
            engine.step(300)
            runs.append(engine.records())
    assert runs[0].tobytes() == runs[1].tobytes()
    assert np.all(np.diff(runs[0]["tick"]) == 1)
    np.testing.assert_array_equal(runs[0]["time_ns"], runs[0]["tick"] * 20_000_000)


@pytest.mark.parametrize("rate", [0.5, 1.0, 1.5])
def test_lead_compensation_on_a_ramp(rate):
    """On a straight ramp x(k) = x0 + s*k the commands are exactly
    dead_time_lag: x(p + r*Td/T) + tau * s * r / T;  mean_delay: x(p + r*(Td+tau)/T)."""
    config = make_figure(1, max_accel=1e6, max_speed=100.0, dead_time=0.05, time_constant=0.07)
    s, x0, T = 0.001, -0.9, 0.02                        # slope [m/tick], start [m], period [s]
    ramp = x0 + s * np.arange(1000)
    expected = {
        "dead_time_lag": lambda p: x0 + s * (p + rate * 0.05 / T) + 0.07 * s * rate / T,
        "mean_delay": lambda p: x0 + s * (p + rate * 0.12 / T),
        "none": lambda p: x0 + s * p,
    }
    for lead, model in expected.items():
        for interpolation in ("linear", "cubic"):
            with Engine(config, make_show(config, [ramp]), lead=lead, rate=rate,
                        interpolation=interpolation, record=True) as engine:
                engine.step(300)
                r = engine.records()
            np.testing.assert_allclose(r["position"], rate * np.arange(300), rtol=0, atol=1e-9)
            np.testing.assert_allclose(r["command"][5:, 0], model(r["position"][5:]),
                                       rtol=0, atol=1e-12, err_msg=f"{lead} {interpolation}")


def servo_response(commands, T, dead_time, tau, substeps=40):
    """Position [unit] at each tick start of a servo that holds each command
    for one tick (zero-order hold), then delays it by dead_time [s] and
    follows through a first-order lag tau [s]; exact discretisation."""
    dt = T / substeps
    delay = int(round(dead_time / dt))
    u = np.repeat(commands, substeps)
    u = np.concatenate([np.full(delay, commands[0]), u])[: len(u)]
    alpha = 1 - np.exp(-dt / tau)
    y = np.empty_like(u)
    y_prev = commands[0]
    for i, ui in enumerate(u):
        y[i] = y_prev
        y_prev += alpha * (ui - y_prev)
    return y[::substeps]


def test_compensation_makes_the_servo_land_on_time():
    """A simulated servo with dead time and lag follows the taught motion far
    better with the default compensation than with the paper's mean delay,
    and that better than with none. The figure's dead time includes the
    half tick that holding each setpoint adds (what identification measures)."""
    T, servo_dead, tau = 0.02, 0.07, 0.15                       # [s]
    config = make_figure(1, dead_time=servo_dead + T / 2, time_constant=tau,
                         max_speed=5, max_accel=50)
    t = np.arange(1500) * T
    taught = 0.5 * np.sin(2 * np.pi * 0.7 * t) * np.minimum(1, t / 2)
    errors = {}
    for lead in ("dead_time_lag", "mean_delay", "none"):
        with Engine(config, make_show(config, [taught]), lead=lead, record=True) as engine:
            engine.step(1500)
            cmd = engine.records()["command"][:, 0]
        y = servo_response(cmd, T, servo_dead, tau)
        errors[lead] = np.sqrt(np.mean((y[200:1400] - taught[200:1400]) ** 2))  # [m]
    assert errors["dead_time_lag"] < 0.005, errors          # 1 % of the 0.5 m amplitude
    assert errors["dead_time_lag"] < 0.1 * errors["mean_delay"], errors
    assert errors["mean_delay"] < 0.5 * errors["none"], errors


def test_end_of_show_holds_the_last_pose_and_flags_it():
    config = make_figure(1, max_accel=1e6, max_speed=100.0)
    with Engine(config, make_show(config, [np.linspace(0, 0.5, 50)]), lead="none",
                record=True) as engine:
        engine.step(80)
        r = engine.records()
    assert np.all(r["flags"][49:] & FLAG_END) and not np.any(r["flags"][:49] & FLAG_END)
    np.testing.assert_array_equal(r["position"][49:], 49.0)
    assert r["command"][-1, 0] == pytest.approx(0.5, abs=1e-12)


def test_rate_zero_holds_and_seek_jumps_smoothly():
    config = make_figure(1, max_speed=0.5, max_accel=2.0)
    show = make_show(config, [np.linspace(-0.5, 0.5, 500)], np.linspace(0, 1, 500))
    with Engine(config, show, lead="none", record=True) as engine:
        engine.step(10)
        engine.set_rate(0.0)
        engine.step(10)
        engine.seek(400.0)
        engine.set_rate(1.0)
        engine.step(200)
        r = engine.records()
    np.testing.assert_array_equal(r["position"][10:20], 10.0)
    assert r["position"][20] == 400.0
    assert np.all(r["flags"][20:40] & FLAG_LIMITED)           # the jump is rate-limited
    check_limits(config, r["command"], show.positions[:, 0])
    np.testing.assert_allclose(r["stored_loudness"][20], 400 / 499, rtol=1e-12)


def test_bad_inputs_are_refused_and_recorded():
    config = make_figure(2)
    show = make_show(config, np.zeros((2, 100)))
    with Engine(config, show, record=True) as engine:
        for bad in (float("nan"), float("inf"), -1.0):
            with pytest.raises(ValueError, match="refused"):
                engine.push_loudness(bad)
        with pytest.raises(ValueError, match="rate nan"):
            engine.set_rate(float("nan"))
        with pytest.raises(ValueError, match="position"):
            engine.seek(1e9)
        engine.push_loudness(0.3)
        engine.step(3)
        r = engine.records()
        assert engine.stats()["bad_input"] == 3
    assert r["flags"][0] & FLAG_BAD_INPUT and not r["flags"][1] & FLAG_BAD_INPUT
    np.testing.assert_array_equal(r["live_loudness"], [0.3, np.nan, np.nan])   # NaN: no new frame
    with pytest.raises(ShowError):
        Engine(config, make_show(config, np.full((2, 10), 5.0)))    # outside the limits
    with pytest.raises(ValueError, match="lead"):
        Engine(config, show, lead="psychic")


def _ticks(messages):
    """[(tick, entries)] from a tick stream: each tick a SYNC, then SETPOINT
    messages of the same tick whose entries together are the tick's."""
    ticks = []
    for m in messages:
        if isinstance(m, protocol.Sync):
            ticks.append((m.tick, []))
        else:
            assert isinstance(m, protocol.Setpoints) and ticks and m.tick == ticks[-1][0], m
            ticks[-1][1].extend(m.entries)
    return ticks


def _decode_stream(data):
    """Ticks of a serial stream, every frame intact."""
    deframer = protocol.Deframer()
    messages = deframer.feed(data)
    assert deframer.rejected == 0 and deframer.counters["bytes"] == len(data), deframer.counters
    return _ticks(messages)


def _decode_can(chunks):
    """Ticks of the engine's CAN records (one bytes object per tick, or concatenated)."""
    decoder = protocol.CanDecoder()
    messages = [m for chunk in chunks for can_id, data in protocol.can_records(chunk)
                for m in decoder.feed(can_id, data)]
    assert decoder.rejected == 0, decoder.errors
    return _ticks(messages)


def _expected_counts(config, commands):
    """(node, channel, counts) of a tick, in the order the sink sends: by node, then channel."""
    return sorted((a.node, a.channel, int(np.rint(a.offset + a.scale * c)))
                  for a, c in zip(config.axes, commands))


def test_fd_sink_writes_frames_to_a_pty(rng):
    config = make_figure(3)
    show = make_show(config, smooth_dance(config, 100, rng))
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        with Engine(config, show, output=slave, record=True) as engine:
            engine.step(20)
            records = engine.records()
            stats = engine.stats()
        data = b""
        os.set_blocking(master, False)
        while True:
            try:
                chunk = os.read(master, 65536)
            except BlockingIOError:
                break
            data += chunk
    finally:
        os.close(master)
        os.close(slave)
    frames = _decode_stream(data)
    assert stats["sink_frames"] == 20 and stats["sink_errors"] == 0
    assert [t for t, _ in frames] == list(range(20))
    for (tick, entries), rec in zip(frames, records):
        assert entries == _expected_counts(config, rec["command"])


def test_ring_sink_feeds_a_pyserial_port(rng):
    config = make_figure(2)
    show = make_show(config, smooth_dance(config, 100, rng))
    port = serial.serial_for_url("loop://", timeout=0)
    with Engine(config, show, output=port, record=True) as engine:
        engine.step(30)
        records = engine.records()
    frames = _decode_stream(port.read(100000))
    port.close()
    assert [t for t, _ in frames] == list(range(30))
    assert frames[7][1] == _expected_counts(config, records["command"][7])


def test_a_vanished_receiver_never_stops_the_tick(rng):
    config = make_figure(2)
    show = make_show(config, smooth_dance(config, 100, rng))
    read_end, write_end = os.pipe()
    os.close(read_end)                                    # the node is gone: EPIPE
    try:
        with Engine(config, show, output=write_end, record=True) as engine:
            engine.step(50)
            stats = engine.stats()
            assert len(engine.records()) == 50
    finally:
        os.close(write_end)
    assert stats["ticks"] == 50 and stats["sink_errors"] == 50 and stats["records_dropped"] == 0


def test_many_axes_span_several_setpoint_records():
    from marionette.config import config_from_dict
    from conftest import figure_dict
    doc = figure_dict(300)
    for j, axis in enumerate(doc["axis"]):
        axis.update(node=j // 100, channel=j % 100)
    config = config_from_dict(doc)
    with Engine(config, make_show(config, np.zeros((300, 10))), output=serial.serial_for_url("loop://", timeout=0),
                record=True) as engine:
        engine.step(1)
        data = engine._writer.read(100000)
    deframer = protocol.Deframer()
    frames = deframer.feed(data)
    # payload 245 bytes: a group is 3 bytes + 4 per channel; a frame is closed
    # when the next entry does not fit (60 in one group, 59 across two)
    assert [type(m) for m in frames] == [protocol.Sync] + [protocol.Setpoints] * 6
    assert [len(m.entries) for m in frames[1:]] == [60, 59, 60, 59, 60, 2]
    assert _decode_stream(data) == [(0, _expected_counts(config, np.zeros(300)))]


def _can_figure(n_axes=12):
    """Axes on nodes 1.. with channels 0..8 (the CAN mapping's), in a shuffled order."""
    from marionette.config import config_from_dict
    from conftest import figure_dict
    doc = figure_dict(n_axes)
    for j, axis in enumerate(doc["axis"]):
        axis.update(node=1 + j // 9, channel=j % 9, scale=-1000.0 if j % 2 else 1000.0, offset=17.0)
    doc["axis"] = doc["axis"][::-1]
    return config_from_dict(doc)


def test_can_sink_feeds_python_can_style_writers(rng):
    config = _can_figure()
    show = make_show(config, smooth_dance(config, 100, rng))

    class Bus:                                  # what CanLink.write gets: one tick's records
        def __init__(self):
            self.chunks = []

        def write(self, records):
            self.chunks.append(records)

    bus = Bus()
    with Engine(config, show, output=bus, protocol="can", record=True) as engine:
        engine.step(25)
        records = engine.records()
        stats = engine.stats()
    assert len(bus.chunks) == 25 and stats["sink_frames"] == 25 and stats["sink_errors"] == 0
    ticks = _decode_can(bus.chunks)
    assert [t for t, _ in ticks] == list(range(25))
    for (tick, entries), rec in zip(ticks, records):
        assert entries == _expected_counts(config, rec["command"])
    # per tick: SYNC and one PDO per three channels of a node (9 + 3 axes: 3 + 1)
    assert [len(c) for c in bus.chunks] == [protocol.CAN_RECORD_BYTES * 5] * 25
    assert stats["sink_bytes"] == sum(map(len, bus.chunks))


def test_can_sink_writes_one_record_per_write_on_a_descriptor(rng):
    import socket
    config = _can_figure(4)
    show = make_show(config, smooth_dance(config, 100, rng))
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)   # keeps write boundaries
    try:
        with Engine(config, show, output=ours.fileno(), protocol="can", record=True) as engine:
            engine.step(6)
            records = engine.records()
        theirs.setblocking(False)
        packets = []
        while True:
            try:
                packets.append(theirs.recv(4096))
            except BlockingIOError:
                break
    finally:
        ours.close()
        theirs.close()
    assert {len(p) for p in packets} == {protocol.CAN_RECORD_BYTES} and len(packets) == 6 * 3
    ticks = _decode_can(packets)
    assert [t for t, _ in ticks] == list(range(6))
    assert ticks[5][1] == _expected_counts(config, records["command"][5])


def test_protocol_must_carry_every_axis():
    from marionette.config import config_from_dict
    from conftest import figure_dict
    port = serial.serial_for_url("loop://", timeout=0)
    show = lambda config: make_show(config, np.zeros((len(config.axes), 5)))   # noqa: E731
    with pytest.raises(ValueError, match="protocol must be"):
        Engine(make_figure(1), show(make_figure(1)), protocol="smoke")
    for change, protocol_name, message in [
            (dict(node=0), "can", "cannot be carried on CAN"),
            (dict(node=1, channel=9), "can", "cannot be carried on CAN"),
            (dict(node=1, scale=1e6), "can", "at most"),
            (dict(node=255), "serial", "broadcast")]:
        doc = figure_dict(1)
        doc["axis"][0].update(change)
        config = config_from_dict(doc)
        with pytest.raises(ValueError, match=message):
            Engine(config, show(config), output=port, protocol=protocol_name)
        Engine(config, show(config), protocol=protocol_name).close()     # no output: nothing to carry
    port.close()


def test_flight_record_file_round_trip(tmp_path, rng):
    config = make_figure(4)
    show = make_show(config, smooth_dance(config, 300, rng), rng.uniform(0, 1, 300))
    path = tmp_path / "flight.bin"
    with Engine(config, show, record=path) as engine:
        engine.step(5000)                                 # more than the ring holds
        in_memory = engine.records()
    meta, records = read_flight_record(path)
    assert meta["axis_names"] == config.axis_names and meta["tick_period"] == 0.02
    assert len(records) == 5000 and np.all(np.diff(records["tick"]) == 1)
    assert records.tobytes() == in_memory.tobytes()
    path.write_bytes(path.read_bytes()[:-3])
    with pytest.raises(ValueError, match="not a whole number"):
        read_flight_record(path)


def test_snapshot_matches_the_last_record(rng):
    config = make_figure(3)
    show = make_show(config, smooth_dance(config, 100, rng))
    with Engine(config, show, record=True) as engine:
        assert engine.snapshot() is None
        engine.step(17)
        snap = engine.snapshot()
        last = engine.records()[-1]
    assert snap.tick == 16 and snap.position == last["position"]
    assert list(snap.commands.values()) == list(last["command"])


def test_step_refuses_while_the_loop_runs():
    config = make_figure(1)
    with Engine(config, make_show(config, np.zeros((1, 10)))) as engine:
        engine.start(priority=0, max_ticks=0)
        with pytest.raises(EngineError, match="real-time loop is running"):
            engine.step(1)
        with pytest.raises(EngineError, match="already running"):
            engine.start(priority=0)
