"""The in-process simulator (SimFigure): node semantics of
firmware_protocol/SPEC.md section 6 on a virtual clock, messages passed
through the real codec both ways."""
import numpy as np
import pytest

from marionette import protocol
from marionette.config import load_config
from marionette.music.bands import N_BANDS, BandMeter, bands
from marionette.music.feature import LoudnessMeter
from marionette.sim.faults import Faults
from marionette.sim.figure import SimFigure

T = 0.02


@pytest.fixture
def figure():
    return load_config(None)


def wire(message):
    """Through the serial codec and back, as on a real line."""
    return protocol.Deframer().feed(protocol.encode_serial(message))[0]


def tick(sim, figure, k, targets=None, poll=protocol.BROADCAST):
    """SYNC k and (unless targets is False) setpoints [unit] per axis; answers."""
    answers = sim.handle(wire(protocol.Sync(k, poll)), k * T)
    if targets is not False:
        x = [a.home for a in figure.axes] if targets is None else targets
        entries = [(a.node, a.channel, int(round(a.offset + a.scale * v))) for a, v in zip(figure.axes, x)]
        answers += sim.handle(wire(protocol.Setpoints(k, entries)), k * T + 0.001)
    return [wire(a) for a in answers]


def statuses(answers, node=None):
    return [a for a in answers if isinstance(a, protocol.Status) and (node is None or a.node == node)]


def test_every_node_answers_every_sync_with_a_heartbeat_at_changes(figure):
    sim = SimFigure(figure)
    first = tick(sim, figure, 0)
    assert sorted(s.node for s in statuses(first)) == [1, 2, 3, 4, 5]
    assert {(a.state, a.seq) for a in first if isinstance(a, protocol.Heartbeat)} == {(protocol.STATE_BOOT, 0)}
    second = tick(sim, figure, 1)
    assert {s.state for s in statuses(second)} == {protocol.STATE_OPERATIONAL}
    assert {(a.node, a.state, a.seq) for a in second if isinstance(a, protocol.Heartbeat)} == {
        (n, protocol.STATE_OPERATIONAL, 1) for n in (1, 2, 3, 4, 5)}
    beats = [sum(isinstance(a, protocol.Heartbeat) for a in tick(sim, figure, k)) for k in range(2, 120)]
    assert sum(beats) == 2 * 5              # at least every 50 ticks, no more
    assert len(statuses(tick(sim, figure, 120, poll=3))) == 1    # a poll of one node


def test_watchdog_holds_for_its_time_then_brakes_within_the_limit(figure):
    sim = SimFigure(figure, watchdog_ticks=5)
    rng = np.random.default_rng(1)
    lo, hi = np.array([a.min for a in figure.axes]), np.array([a.max for a in figure.axes])
    for k in range(60):          # a fast sweep so the axes move when the host goes
        tick(sim, figure, k, lo + (hi - lo) * (0.5 + 0.3 * np.sin(k / 6 + rng.uniform(0, 0.1))))
    flags, xs = [], []
    for k in range(60, 140):
        s = statuses(tick(sim, figure, k, targets=False), node=1)[0]
        flags.append(s.flags)
        xs.append(sim.positions())
    tripped = [bool(f & protocol.FLAG_WATCHDOG) for f in flags]
    # the last setpoint came at 59*T + 1 ms: the node trips 5 ticks later
    assert tripped.index(True) == 5 and all(tripped[5:])
    x = np.array(xs)
    a = np.diff(x, 2, axis=0) / T ** 2
    assert np.all(np.abs(a) <= np.array([ax.max_accel for ax in figure.axes]) * 1.001)
    assert np.abs(x[-1] - x[-2]).max() < 1e-4                  # at rest (the lag's creep)
    # a new setpoint clears it: the node follows again
    s = statuses(tick(sim, figure, 140) + tick(sim, figure, 141), node=1)[-1]
    assert not s.flags & protocol.FLAG_WATCHDOG and s.state == protocol.STATE_OPERATIONAL


def test_estop_latches_ignores_setpoints_once_nacked_and_release_holds(figure):
    sim = SimFigure(figure)
    for k in range(10):
        tick(sim, figure, k)
    sim.handle(wire(protocol.Estop()), 10 * T)
    far = [a.max for a in figure.axes]
    answers = [a for k in range(11, 40) for a in tick(sim, figure, k, far)]
    nacks = [a for a in answers if isinstance(a, protocol.Nack)]
    assert sorted(n.node for n in nacks) == [1, 2, 3, 4, 5]
    assert {n.reason for n in nacks} == {protocol.REASON_ESTOP_LATCHED}
    assert all(s.flags & protocol.FLAG_ESTOP and s.state == protocol.STATE_STOPPED
               for s in statuses(answers))
    home = np.array([a.home for a in figure.axes])
    np.testing.assert_allclose(sim.positions(), home, atol=1e-9)      # never went to `far`
    sim.handle(wire(protocol.EstopRelease()), 40 * T)
    s = statuses(tick(sim, figure, 41, targets=False))
    assert all(not x.flags & protocol.FLAG_ESTOP and x.state == protocol.STATE_PRE_OPERATIONAL for x in s)
    for k in range(42, 90):
        tick(sim, figure, k, far)
    assert np.all(sim.positions() > home)                          # follows again


def test_limits_clamp_and_flag_once_stale_and_gaps_counted(figure):
    sim = SimFigure(figure)
    tick(sim, figure, 0)
    a = figure.axes[0]
    beyond = [a.max + 1.0] + [x.home for x in figure.axes[1:]]
    s = statuses(tick(sim, figure, 1, beyond), node=a.node)[0]
    s = statuses(tick(sim, figure, 2), node=a.node)[0]
    assert s.flags & protocol.FLAG_LIMIT
    s = statuses(tick(sim, figure, 3), node=a.node)[0]
    assert not s.flags & protocol.FLAG_LIMIT                       # cleared by the STATUS
    tick(sim, figure, 7)                                            # ticks 4..6 skipped
    old = [(x.node, x.channel, 0) for x in figure.axes]
    sim.handle(wire(protocol.Setpoints(5, old)), 7 * T + 0.002)    # a stale frame after 7
    s = statuses(tick(sim, figure, 8), node=1)[0]
    assert s.seq_gaps == 3 and s.rejected == 1
    assert sim.nodes[1].model.command[0] == pytest.approx(figure.axes[0].home)   # not taken
    # a SYNC that is not newer means the host restarted: any tick is taken again
    tick(sim, figure, 0)
    assert statuses(tick(sim, figure, 1), node=1)[0].rejected == 1


def test_config_is_acknowledged_or_refused(figure):
    sim = SimFigure(figure)
    good = protocol.node_config(figure, 1, watchdog_ticks=9, seq=4)
    (ack,) = sim.handle(wire(good), 0.0)
    assert ack.reason == protocol.REASON_ACCEPTED and ack.ref_seq == 4 and sim.nodes[1].watchdog_ticks == 9
    bad = protocol.Config(2, ((0, 10, 5, 1, 1),), 5, 20000, seq=5)  # min > max
    (nack,) = sim.handle(wire(bad), 0.0)
    assert nack.reason == protocol.REASON_BAD_CONFIG
    other = protocol.Config(2, ((7, 0, 10, 1, 1),), 5, 20000, seq=6)    # node 2 has channel 0 only
    (nack,) = sim.handle(wire(other), 0.0)
    assert nack.reason == protocol.REASON_BAD_CHANNEL


def test_a_silenced_node_neither_listens_nor_answers(figure):
    faults = Faults()
    sim = SimFigure(figure, faults)
    tick(sim, figure, 0)
    faults.apply("silence 2")
    assert sorted(s.node for s in statuses(tick(sim, figure, 1))) == [1, 3, 4, 5]
    faults.apply("resume 2")
    assert sorted(s.node for s in statuses(tick(sim, figure, 2))) == [1, 2, 3, 4, 5]


def test_loudness_answered_at_a_sync_measures_the_period_before_it(figure):
    # music whose level changes every 7 ms: a frame taken on any other grid
    # than [t - T, t) gives another value
    rng = np.random.default_rng(4)
    rate = 16000.0                                                      # [Hz]
    n = int(3.0 * rate)
    level = 10.0 ** rng.uniform(-3, 0, int(3.0 / 0.007) + 1)           # [full scale]
    ts = np.arange(n) / rate                                            # sample times [s]
    samples = level[(ts / 0.007).astype(int)] * np.sin(2 * np.pi * 440.0 * ts)
    sim = SimFigure(figure, music=(samples, rate), music_node=5)
    meter = LoudnessMeter(rate, T)
    phase = rng.uniform(0.0, T)                                         # host ticks vs music start [s]
    values, frames = [], []
    for k in range(140):
        t = k * T + phase                                               # SYNC arrival, model time [s]
        got = [a for a in sim.handle(wire(protocol.Sync(k, protocol.BROADCAST)), t)
               if isinstance(a, protocol.Loudness)]
        start = int(np.floor((t - T) * rate))
        if start < 0:
            assert got == []                                            # not a whole period yet
            continue
        assert len(got) == 1 and got[0].node == 5
        want = meter.frame_loudness(samples[start:start + meter.frame_len])[0]
        assert got[0].value == pytest.approx(want, rel=1e-6)           # float32 on the wire
        values.append(got[0].value)
        frames.append(got[0].frame)
    assert frames == list(range(len(frames)))                          # the node's frame counter
    assert len(set(values)) > 100                                       # the level really moved


@pytest.mark.parametrize("music_bands", [True, False])
def test_a_band_node_sends_the_bands_of_the_period_before_the_sync(figure, music_bands):
    rng = np.random.default_rng(5)
    rate = 16000.0                                                      # [Hz]
    ts = np.arange(int(2.0 * rate)) / rate                              # [s]
    # a tone whose pitch and level jump every 30 ms, so every band moves
    f = 10 ** rng.uniform(np.log10(60), np.log10(4000), 70)[(ts / 0.03).astype(int)]      # [Hz]
    level = 10.0 ** rng.uniform(-3, 0, 70)[(ts / 0.03).astype(int)]    # [full scale]
    samples = level * np.sin(2 * np.pi * np.cumsum(f) / rate)
    sim = SimFigure(figure, music=(samples, rate), music_node=5, music_bands=music_bands)
    window = BandMeter(rate, T).window_len                              # [samples]
    phase = rng.uniform(0.0, T)
    checked = 0
    for k in range(95):
        t = k * T + phase                                               # SYNC arrival [s]
        got = [a for a in sim.handle(wire(protocol.Sync(k, protocol.BROADCAST)), t)
               if isinstance(a, protocol.Loudness)]
        end = int(np.floor((t - T) * rate)) + int(rate * T)             # the period's end [samples]
        if not got or end < window:
            continue
        if not music_bands:
            assert got[0].bands is None
            continue
        # BandMeter on the same audio: the window ending where the period ends
        want = bands(samples[end - window:end], rate)[-1]
        assert len(got[0].bands) == N_BANDS
        assert np.max(np.abs(20 * np.log10(np.array(got[0].bands) / want))) <= 0.25 + 1e-6
        checked += 1
    assert checked > 80 or not music_bands


def _sealed(body: bytes) -> bytes:
    return protocol.cobs_encode(body + protocol.crc32c(body).to_bytes(4, "little")) + b"\0"


def test_refused_frames_are_nacked_by_their_node_alone_and_counted_by_it(figure):
    sim = SimFigure(figure)
    deframer = protocol.Deframer()
    tick(sim, figure, 0)
    tick(sim, figure, 1)
    estop = protocol.encode_body(protocol.Estop(2, seq=33))[:-4]
    frames = {protocol.REASON_BAD_VERSION: b"\x02" + estop[1:],
              protocol.REASON_BAD_TYPE: estop[:1] + b"\x42" + estop[2:],
              protocol.REASON_BAD_LENGTH: estop + b"\x00"}
    last_sync = 1
    for reason, body in frames.items():
        for refused in deframer.feed(_sealed(body), refusals=True):
            assert sim.handle(refused, 0.03) == []
        answers = tick(sim, figure, 2 + reason)
        (nack,) = [a for a in answers if isinstance(a, protocol.Nack)]
        assert (nack.node, nack.reason, nack.ref_type, nack.ref_seq, nack.seq) == (
            2, reason, body[1], 33, last_sync)          # seq: the node's last SYNC before it
        last_sync = 2 + reason
    rejected = {s.node: s.rejected for s in statuses(tick(sim, figure, 9))}
    assert rejected == {1: 0, 2: 3, 3: 0, 4: 0, 5: 0}
    # addressed to a node not on this figure: ignored by all, not counted
    for refused in deframer.feed(_sealed(protocol.encode_body(protocol.Estop(77))[:-4] + b"\0"),
                                 refusals=True):
        assert sim.handle(refused, 0.2) == []
    answers = tick(sim, figure, 10)
    assert {s.node: s.rejected for s in statuses(answers)} == rejected
    assert not [a for a in answers if isinstance(a, protocol.Nack)]


def test_can_config_incomplete_and_bad_value_are_nacked_at_once(figure):
    sim = SimFigure(figure)
    decoder = protocol.CanDecoder()
    frames = protocol.encode_can(protocol.node_config(figure, 1, seq=12))
    incomplete = [f for f in frames if f[1][0] != 0x13 or f[1][1] != 0]    # channel 0's ACCEL left out
    got = [m for i, d in incomplete for m in decoder.feed(i, d, refusals=True)]
    assert [type(m) for m in got] == [protocol.Refused]
    (nack,) = sim.handle(got[0], 0.0)
    assert (nack.node, nack.reason, nack.ref_type, nack.ref_seq) == (
        1, protocol.REASON_CONFIG_INCOMPLETE, protocol.CONFIG, 12)
    assert decoder.feed(*frames[0], refusals=True) == []                   # BEGIN
    bad = (protocol.CAN_CONFIG + 1, bytes.fromhex("02ff000000000100"))     # WATCHDOG 65536
    (refused,) = decoder.feed(*bad, refusals=True)
    (nack,) = sim.handle(refused, 0.0)
    assert nack.reason == protocol.REASON_BAD_VALUE and nack.ref_type == protocol.CONFIG
    (config,) = [m for i, d in frames for m in decoder.feed(i, d, refusals=True)]
    (ack,) = sim.handle(config, 0.0)
    assert ack.reason == protocol.REASON_ACCEPTED and ack.ref_seq == 12
