"""The protocol's Python API (marionette.protocol) on the C codec: golden
vectors, random round trips, the deframer on noisy streams, the CAN
receiver, and the DBC against the codec (cantools)."""
from __future__ import annotations

import json
import runpy
import struct
from pathlib import Path

import cantools
import numpy as np
import pytest

from marionette import _protocol as _p
from marionette import protocol as P
from marionette.config import load_config

ROOT = Path(__file__).resolve().parents[1]
VECTORS = ROOT / "firmware_protocol" / "vectors"
DBC = ROOT / "firmware_protocol" / "marionette.dbc"
SEED = 20261122
DBC_NODES = 16              # nodes the committed DBC lists


# -- messages from the vectors' JSON (wire field names) ---------------------

def from_json(d: dict):
    t = d["type"]
    if t == "SYNC":
        return P.Sync(d["seq"], d["poll"])
    if t == "SETPOINT":
        return P.Setpoints(d["seq"], [tuple(e) for e in d["entries"]])
    if t == "ESTOP":
        return P.Estop(d["node"], d["seq"])
    if t == "ESTOP_RELEASE":
        return P.EstopRelease(d["node"], d["seq"])
    if t == "CONFIG":
        return P.Config(d["node"], [P.ChannelConfig(*c) for c in d["channels"]], d["watchdog_ticks"],
                        d["tick_period_us"], d["seq"])
    if t == "STATUS":
        return P.Status(d["node"], d["seq"], d["flags"], d["state"], d["rejected"], d["seq_gaps"],
                        d["positions"])
    if t == "HEARTBEAT":
        return P.Heartbeat(d["node"], d["state"], d["seq"])
    if t == "LOUDNESS":
        bands = [P.band_level(c) for c in d["bands"]] if "bands" in d else None
        return P.Loudness(d["node"], d["seq"], d["value"], bands)
    assert t == "NACK", t
    return P.Nack(d["node"], d["reason"], d["ref_type"], d["ref_seq"], d["flags"], d["seq"])


def serial_vectors():
    return json.loads((VECTORS / "serial.json").read_text())


def can_vectors():
    return json.loads((VECTORS / "can.json").read_text())


def test_vectors_cover_every_message_type():
    kinds = {v["message"]["type"] for v in serial_vectors()}
    assert kinds == set(P.TYPE_NAMES.values())
    assert {v["message"]["type"] for v in can_vectors()} == kinds


@pytest.mark.parametrize("vector", serial_vectors(), ids=lambda v: v["name"])
def test_serial_golden_vector(vector):
    message = from_json(vector["message"])
    wire, body = bytes.fromhex(vector["wire"]), bytes.fromhex(vector["body"])
    assert P.encode_serial(message) == wire
    assert P.encode_body(message) == body
    assert P.decode_serial(wire) == message
    assert P.decode_serial(wire[:-1]) == message                # the 0x00 is optional
    assert P.decode_body(body) == message
    assert P.cobs_encode(body) + b"\0" == wire and P.cobs_decode(wire[:-1]) == body
    assert P.crc32c(body[:-4]) == int.from_bytes(body[-4:], "little")
    assert body[0] == P.VERSION and body[1] == getattr(P, vector["message"]["type"])
    assert b"\0" not in wire[:-1] and len(wire) <= P.WIRE_MAX


def test_refused_vectors():
    vectors = json.loads((VECTORS / "refused.json").read_text())
    assert {v["link"] for v in vectors} == {"serial", "can"}
    for v in vectors:
        code = getattr(P, v["error"])
        if v["link"] == "serial":
            with pytest.raises(P.ProtocolError) as err:
                P.decode_serial(bytes.fromhex(v["wire"]))
            assert err.value.code == code, v["name"]
            continue
        rx = _p.CanReceiver()
        for can_id, data in v["prefix"]:
            assert rx.feed(can_id, bytes.fromhex(data))[0] >= 0, v["name"]
        (can_id, data), = v["frame"]
        assert rx.feed(can_id, bytes.fromhex(data))[0] == code, v["name"]
        assert _p.reason_of(code) == v["reason"], v["name"]


def test_serial_vectors_as_one_stream():
    vectors = serial_vectors()
    deframer = P.Deframer()
    stream = b"".join(bytes.fromhex(v["wire"]) for v in vectors)
    assert deframer.feed(stream) == [from_json(v["message"]) for v in vectors]
    assert deframer.counters["frames_ok"] == len(vectors) and deframer.rejected == 0


@pytest.mark.parametrize("vector", can_vectors(), ids=lambda v: v["name"])
def test_can_golden_vector(vector):
    message = from_json(vector["message"])
    frames = [(i, bytes.fromhex(d)) for i, d in vector["frames"]]
    prefix = [(i, bytes.fromhex(d)) for i, d in vector["prefix"]]
    assert P.encode_can(message) == frames
    decoded = P.decode_can_frames(prefix + frames)
    assert decoded[len(prefix):] == [from_json(d) for d in vector["decoded"]]
    for record in (P.can_record(i, d) for i, d in frames):
        assert len(record) == P.CAN_RECORD_BYTES
    assert P.can_records(b"".join(P.can_record(i, d) for i, d in frames)) == frames


# -- random messages --------------------------------------------------------

def counts(rng, can=False):
    hi = P.CAN_COUNTS_MAX if can else 2**31 - 1
    lo = -hi if can else -2**31
    return int(rng.choice([0, lo, hi, rng.integers(-300, 301), rng.integers(lo, hi + 1)]))


def random_band(rng):
    """A band level [full scale]: silent, far below the lowest code, beyond the top, or in range."""
    return float(rng.choice([0.0, 1e-9, 5.0, 10 ** rng.uniform(-6, 0.3)]))


def random_message(rng, can=False, nodes=DBC_NODES):
    kind = int(rng.integers(9))
    node = int(rng.integers(1, nodes + 1)) if can else int(rng.integers(0, 255))
    seq = int(rng.integers(0, 2**32))
    if kind == 0:
        return P.Sync(seq, P.BROADCAST if can or rng.random() < 0.3 else int(rng.integers(256)))
    if kind == 1:
        if can:     # a few nodes, each with some of its channels, in order
            entries = [(int(n), int(c), counts(rng, True))
                       for n in sorted(rng.choice(np.arange(1, nodes + 1), int(rng.integers(1, 4)), False))
                       for c in sorted(rng.choice(9, int(rng.integers(1, 10)), False))]
        else:
            n = int(rng.integers(1, 35))           # 34 single-entry groups always fit a frame
            entries = [(int(rng.integers(0, 255)), int(rng.integers(0, 256)), counts(rng)) for _ in range(n)]
        return P.Setpoints(seq, entries)
    if kind in (2, 3):
        cls = P.Estop if kind == 2 else P.EstopRelease
        return cls(P.BROADCAST if rng.random() < 0.3 else node, 0 if can else seq)
    if kind == 4:
        n = int(rng.integers(0, 10 if can else 15))
        channels = rng.choice(9 if can else 256, n, replace=False)
        return P.Config(node, [P.ChannelConfig(int(c), counts(rng), counts(rng), int(rng.integers(1, 2**32)),
                                               int(rng.integers(1, 2**32))) for c in channels],
                        int(rng.integers(0, 2**16)), int(rng.integers(0, 2**32)), seq)
    if kind == 5:
        n = int(rng.integers(0, 10 if can else 60))
        return P.Status(node, seq & 0xFF if can else seq, int(rng.integers(0, 32)),
                        int(rng.choice([P.STATE_BOOT, P.STATE_STOPPED, P.STATE_OPERATIONAL,
                                        P.STATE_PRE_OPERATIONAL])),
                        int(rng.integers(0, 2**16)), int(rng.integers(0, 2**16)),
                        [counts(rng, can) for _ in range(n)])
    if kind == 6:
        return P.Heartbeat(node, int(rng.choice([0, 4, 5, 127])), 0 if can else seq)
    if kind == 7:
        value = float(rng.choice([0.0, rng.uniform(0, 2), rng.uniform(0, 1e30)]))
        if rng.random() < 0.5:
            return P.Loudness(node, seq, value)
        n = int(rng.integers(1, (P.CAN_BANDS_MAX if can else P.BANDS_MAX) + 1))
        return P.Loudness(node, seq, value, [random_band(rng) for _ in range(n)])
    return P.Nack(node, int(rng.integers(0, 2**16)), int(rng.integers(256)), seq, int(rng.integers(0, 32)),
                  0 if can else seq)


def test_serial_round_trips_of_random_messages():
    rng = np.random.default_rng(SEED)
    deframer = P.Deframer()
    stream, sent = bytearray(), []
    for _ in range(3000):
        m = random_message(rng)
        wire = P.encode_serial(m)
        assert P.decode_serial(wire) == m
        stream += wire
        sent.append(m)
    # fed in chunks of any size, the stream gives every message back in order
    cuts = np.sort(rng.integers(0, len(stream), 400))
    got = []
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(stream)]):
        got += deframer.feed(bytes(stream[a:b]))
    assert got == sent
    assert deframer.counters["bytes"] == len(stream) and deframer.rejected == 0


def test_can_round_trips_of_random_messages():
    rng = np.random.default_rng(SEED + 1)
    for _ in range(3000):
        m = random_message(rng, can=True)
        frames = P.encode_can(m)
        assert all(0 <= i < 0x800 and len(d) <= 8 for i, d in frames)
        if isinstance(m, P.Setpoints):
            decoded = P.decode_can_frames([(P.CAN_SYNC, bytes([m.tick & 0xFF]))] + frames)
            assert decoded[0] == P.Sync(m.tick & 0xFF)
            assert all(d.tick == m.tick & 0xFF for d in decoded[1:])
            assert [e for d in decoded[1:] for e in d.entries] == list(m.entries)
        elif isinstance(m, P.Sync):
            assert P.decode_can_frames(frames) == [P.Sync(m.tick & 0xFF)]
        else:
            if isinstance(m, P.Status):                 # joined whatever the order
                frames = [frames[i] for i in rng.permutation(len(frames))]
            assert P.decode_can_frames(frames) == [m]


def test_deframer_resynchronises_after_garbage():
    rng = np.random.default_rng(SEED + 2)
    deframer = P.Deframer()
    for round_ in range(300):
        garbage = rng.integers(0, 256, int(rng.integers(1, 700))).astype(np.uint8).tobytes()
        if round_ % 3 == 0:
            garbage = garbage.replace(b"\0", b"\1")     # runs past the buffer: dropped at the 0x00
        m = random_message(rng)
        got = deframer.feed(garbage + b"\0" + P.encode_serial(m))
        assert got[-1] == m, round_
    c = deframer.counters
    assert c["too_long"] > 0 and c["garbage_bytes"] > 0 and c["frames_ok"] >= 300
    assert deframer.rejected == sum(c[k] for k in ("crc_errors", "cobs_errors", "too_long",
                                                   "too_short", "decode_errors"))


def test_corrupted_frames_are_refused_with_a_reason():
    rng = np.random.default_rng(SEED + 3)
    for _ in range(300):
        m = random_message(rng)
        body = bytearray(P.encode_body(m))
        cut = int(rng.integers(0, len(body)))
        with pytest.raises(P.ProtocolError):
            P.decode_body(bytes(body[:cut]))
        bit = int(rng.integers(0, 8 * len(body)))
        body[bit // 8] ^= 1 << (bit % 8)
        with pytest.raises(P.ProtocolError) as err:
            P.decode_serial(P.cobs_encode(bytes(body)))
        assert err.value.code == P.E_CRC
    with pytest.raises(P.ProtocolError) as err:
        P.decode_serial(b"\x05\x01\x00")
    assert err.value.code == P.E_COBS
    with pytest.raises(ValueError):
        P.cobs_decode(b"\x09\x01")


def _sealed(body: bytes) -> bytes:
    """A frame of these header and payload bytes with a correct CRC."""
    return P.cobs_encode(body + P.crc32c(body).to_bytes(4, "little")) + b"\0"


def test_good_crc_bad_content_is_refused_and_can_be_nacked():
    sync = P.encode_body(P.Sync(9))[:-4]
    frames = [_sealed(b"\x02" + sync[1:]),                            # version 2
              _sealed(sync[:1] + b"\x42" + sync[2:]),                 # unknown type
              _sealed(sync + b"\x00"),                                # SYNC of 2 bytes
              _sealed(P.encode_body(P.Status(3, 4))[:-4][:7] + b"\x20\x05" + b"\0" * 4)]   # reserved flag
    reasons = [P.REASON_BAD_VERSION, P.REASON_BAD_TYPE, P.REASON_BAD_LENGTH, P.REASON_BAD_VALUE]
    deframer = P.Deframer()
    got = deframer.feed(b"".join(frames) + P.encode_serial(P.Sync(10)), refusals=True)
    assert got[:4] == [P.Refused(reasons[0], P.SYNC, 255, 9), P.Refused(reasons[1], 0x42, 255, 9),
                       P.Refused(reasons[2], P.SYNC, 255, 9), P.Refused(reasons[3], P.STATUS, 3, 4)]
    assert got[4] == P.Sync(10)
    assert deframer.counters["decode_errors"] == 4
    assert P.Deframer().feed(frames[0]) == []                       # not listed unless asked


def test_encoder_refuses_what_the_decoder_would():
    bad = [P.Status(255, 1), P.Status(1, 1, flags=0x20), P.Status(1, 1, state=3),
           P.Heartbeat(1, 9), P.Setpoints(1, []), P.Setpoints(1, [(255, 0, 0)]),
           P.Config(P.BROADCAST), P.Nack(1, 0, flags=0x80), P.Loudness(1, 1, -1.0),
           P.Loudness(1, 1, float("nan")), P.Loudness(1, 1, float("inf")), P.Sync(-1),
           P.Setpoints(2**32, [(1, 0, 0)]), P.Setpoints(1, [(1, 0, 2**31)]),
           P.Status(1, 1, positions=[0] * (P.STATUS_MAX + 1)),
           P.Loudness(1, 1, 0.5, [0.1] * (P.BANDS_MAX + 1)), P.Loudness(1, 1, 0.5, [-0.1])]
    for m in bad:
        with pytest.raises(P.ProtocolError):
            P.encode_serial(m)
    with pytest.raises(TypeError):
        P.encode_serial("SYNC")
    can_bad = [P.Sync(1, poll=3), P.Setpoints(1, [(0, 0, 0)]), P.Setpoints(1, [(128, 0, 0)]),
               P.Setpoints(1, [(1, 9, 0)]), P.Setpoints(1, [(1, 0, P.CAN_COUNTS_MAX + 1)]),
               P.Status(1, 1, positions=[0] * 10), P.Status(1, 1, positions=[-P.CAN_COUNTS_MAX - 1]),
               P.Config(1, [(9, 0, 1, 1, 1)]), P.Config(1, [(0, 0, 1, 1, 1), (0, 0, 1, 1, 1)])]
    for m in can_bad:
        with pytest.raises(P.ProtocolError):
            P.encode_can(m)


def test_setpoints_of_any_size_split_into_frames():
    rng = np.random.default_rng(SEED + 4)
    for n in (1, 60, 61, 200, 1000):
        entries = [(j // 100, j % 100, int(rng.integers(-10**6, 10**6))) for j in range(n)]
        m = P.Setpoints(77, entries)
        wire = P.encode_serial(m)
        got = P.Deframer().feed(wire)
        assert all(g.tick == 77 and len(g.entries) <= P.SETPOINT_MAX for g in got)
        assert [e for g in got for e in g.entries] == entries
        assert all(len(f) + 1 <= P.WIRE_MAX for f in wire.split(b"\0")[:-1])
        can = [(j // 9 + 1, j % 9, c // 2) for j, (_, _, c) in enumerate(entries[:900])]
        frames = P.encode_can(P.Setpoints(77, can))
        decoded = P.decode_can_frames([(P.CAN_SYNC, b"\x4d")] + frames)
        assert [e for d in decoded[1:] for e in d.entries] == can
        assert len(frames) == sum(1 for j in range(len(can)) if j % 3 == 0)


def test_can_receiver_ticks_staleness_and_joins():
    d = P.CanDecoder()
    assert d.tick is None
    pdo = P.encode_can(P.Setpoints(5, [(3, 4, -7)]))[0]
    assert d.feed(*pdo) == [] and d.errors == {P.E_STALE: 1}      # no SYNC yet
    tick = 250
    assert d.feed(P.CAN_SYNC, bytes([tick])) == [P.Sync(250)]
    for _ in range(600):                                          # unwrapped past 255
        tick += 1
        assert d.feed(P.CAN_SYNC, bytes([tick & 0xFF])) == [P.Sync(tick)]
    assert d.tick == tick
    good = P.encode_can(P.Setpoints(tick, [(3, 4, -7)]))[0]
    assert d.feed(*good) == [P.Setpoints(tick, [(3, 4, -7)])]
    assert d.feed(*P.encode_can(P.Setpoints(tick - 1, [(3, 4, -7)]))[0]) == []
    assert d.counters["stale"] == 2
    # a status's tick is the latest SYNC's at or before it
    status = P.Status(9, tick - 3, positions=[1, 2, 3, 4])
    frames = P.encode_can(status)
    assert [m for f in frames[::-1] for m in d.feed(*f)] == [status]
    # a frame lost from a status: nothing comes; the next one comes whole
    nxt = P.Status(9, tick, positions=[5, 6, 7, 8])
    assert [m for f in frames[:-1] for m in d.feed(*f)] == []
    assert [m for f in P.encode_can(nxt) for m in d.feed(*f)] == [nxt]
    # a config with a parameter lost is refused at APPLY
    config = P.Config(9, [(0, -5, 5, 100, 1000), (3, 0, 9, 10, 20)], 7, seq=1234)
    frames = P.encode_can(config)
    assert len(frames) == 3 + 4 * 2 and P.decode_can_frames(frames) == [config]
    del frames[4]
    assert P.decode_can_frames(frames) == []
    for can_id, data in [(0x000, b""), (0x581, bytes(8)), (0x701, bytes(8)), (0x080, b"\1\2")]:
        before = d.rejected
        assert d.feed(can_id, data) == [] and d.rejected == before + 1


def test_can_records_layout():
    frames = [(0x080, b"\x07"), (0x201, bytes(range(8))), (0x7FF, b"")]
    buf = b"".join(P.can_record(i, d) for i, d in frames)
    assert len(buf) == 3 * 16
    assert struct.unpack_from("<IB3x", buf, 16) == (0x201, 8) and buf[24:32] == bytes(range(8))
    assert P.can_records(buf) == frames
    with pytest.raises(P.ProtocolError):
        P.can_records(buf[:-1])


def test_node_config_of_the_bundled_figure():
    figure = load_config(None)
    node1 = P.node_config(figure, 1, watchdog_ticks=4, seq=3)
    assert node1.watchdog_ticks == 4 and node1.tick_period_us == 20000 and node1.seq == 3
    assert [c.channel for c in node1.channels] == list(range(9))
    assert node1.channels[0] == P.ChannelConfig(0, 0, 24000, 40000, 240000)
    node5 = P.node_config(figure, 5)
    assert node5.channels[1] == P.ChannelConfig(1, -1952, 3248, 8000, 40000)
    for node in (1, 2, 3, 4, 5):
        c = P.node_config(figure, node)
        assert P.config_reason(c) == P.REASON_ACCEPTED
        assert P.decode_serial(P.encode_serial(c)) == c
        assert P.decode_can_frames(P.encode_can(c)) == [c]
    assert P.config_reason(P.Config(1, [(0, 5, 4, 1, 1)])) == P.REASON_BAD_CONFIG
    assert P.config_reason(P.Config(1, [(0, 4, 5, 1, 1)], watchdog_ticks=0)) == P.REASON_BAD_CONFIG
    with pytest.raises(ValueError, match="no axis"):
        P.node_config(figure, 9)


def test_crc_and_cobs():
    assert P.crc32c(b"123456789") == 0xE3069283
    assert P.crc32c(b"") == 0
    rng = np.random.default_rng(SEED + 5)
    for n in list(range(600)) + [1000, 2000]:
        data = rng.integers(0, 256 if n % 3 else 2, n).astype(np.uint8).tobytes()
        enc = P.cobs_encode(data)
        assert b"\0" not in enc and len(enc) <= n + n // 254 + 1
        assert P.cobs_decode(enc) == data
    assert P.cobs_encode(b"\x11" * 254) == b"\xff" + b"\x11" * 254 + b"\x01"


def test_loudness_is_float32_on_the_wire():
    m = P.Loudness(1, 2, 0.1)
    assert m.value == np.float32(0.1) and m.value != 0.1
    assert P.decode_serial(P.encode_serial(m)) == m


def test_band_levels_are_bytes_of_half_a_db():
    rng = np.random.default_rng(SEED + 7)
    levels = 10 ** rng.uniform(-6, 0.3, 2000)           # -120 dB .. +6 dB re full scale
    back = np.array([P.band_level(P.band_code(x)) for x in levels])
    assert np.max(np.abs(20 * np.log10(back / levels))) <= 0.25 + 1e-6
    assert [P.band_code(x) for x in (0.0, 1e-9, 10 ** (-121.2 / 20), 10 ** (-121.3 / 20))] == \
        [P.BAND_SILENT, P.BAND_SILENT, 254, P.BAND_SILENT]
    assert P.band_code(2.0) == 0 and P.band_code(100.0) == 0          # +6 dB and louder: the top code
    assert P.band_level(P.BAND_SILENT) == 0.0 and P.band_level(0) == pytest.approx(10 ** (6 / 20))
    assert all(P.band_code(P.band_level(c)) == c for c in range(256))
    for bad in (-1e-3, float("nan"), float("inf")):
        with pytest.raises(P.ProtocolError, match="band level"):
            P.band_code(bad)
        with pytest.raises(P.ProtocolError, match="band level"):
            P.encode_serial(P.Loudness(1, 1, 0.5, [0.1, bad]))


def test_one_band_and_band_loudness_on_both_links():
    one = P.Loudness(3, 70, 0.5)
    six = P.Loudness(3, 71, 0.5, [0.5, 0.25, 0.1, 0.01, 1e-4, 0.0])
    assert six.bands[-1] == 0.0 and six.bands[0] == pytest.approx(0.5, rel=0.03)
    assert len(P.encode_body(one)) == 7 + 4 + 4 and len(P.encode_body(six)) == 7 + 4 + 1 + 6 + 4
    assert P.Deframer().feed(P.encode_serial(one) + P.encode_serial(six)) == [one, six]
    assert [i for i, _ in P.encode_can(one)] == [P.CAN_LOUDNESS + 3]
    assert [i for i, _ in P.encode_can(six)] == [P.CAN_BANDS + 3, P.CAN_LOUDNESS + 3]
    assert P.decode_can_frames(P.encode_can(one) + P.encode_can(six)) == [one, six]
    # the bands frame lost: the LOUDNESS still comes, without bands
    assert P.decode_can_frames(P.encode_can(six)[1:]) == [P.Loudness(3, 71, 0.5)]
    assert P.Loudness(3, 1, 0.5, []) == P.Loudness(3, 1, 0.5)      # no bands is the one-band form
    with pytest.raises(P.ProtocolError):
        P.encode_can(P.Loudness(3, 1, 0.5, [0.1] * (P.CAN_BANDS_MAX + 1)))
    with pytest.raises(P.ProtocolError):
        P.encode_serial(P.Loudness(3, 1, 0.5, [0.1] * (P.BANDS_MAX + 1)))


# -- the DBC and the codec ----------------------------------------------------

def test_committed_dbc_is_what_the_generator_writes():
    make_dbc = runpy.run_path(str(ROOT / "firmware_protocol" / "tools" / "make_dbc.py"))
    assert DBC.read_text() == make_dbc["build"](DBC_NODES)


def expected_signals(message, frames):
    """What each frame of a message must decode to in the DBC, from the
    message's fields: [(can_id, {signal: value})]."""
    m = message
    if isinstance(m, P.Sync):
        return [(P.CAN_SYNC, {"counter": m.tick & 0xFF})]
    if isinstance(m, (P.Estop, P.EstopRelease)):
        return [(P.CAN_ESTOP if isinstance(m, P.Estop) else P.CAN_ESTOP_RELEASE, {"node": m.node})]
    if isinstance(m, P.Heartbeat):
        return [(P.CAN_HEARTBEAT + m.node, {"state": m.state})]
    if isinstance(m, P.Loudness):
        out = [(P.CAN_LOUDNESS + m.node, {"frame": m.frame, "loudness": m.value})]
        if m.bands is None:
            return out
        codes = [P.band_code(b) for b in m.bands] + [0] * (P.CAN_BANDS_MAX - len(m.bands))
        return [(P.CAN_BANDS + m.node, {"counter": m.frame & 0xF, "bands": len(m.bands),
                                         **{f"band{k}": c for k, c in enumerate(codes)}})] + out
    if isinstance(m, P.Nack):
        return [(P.CAN_EMCY + m.node, {"reason": m.reason, "flags": m.flags, "ref_type": m.ref_type,
                                       "ref_seq": m.ref_seq})]
    none = -P.CAN_COUNTS_MAX - 1
    if isinstance(m, P.Setpoints):
        pdos = {}
        for node, channel, c in m.entries:
            sig = pdos.setdefault(P.CAN_SETPOINT + 0x100 * (channel // 3) + node,
                                  {"counter": m.tick & 0xF, **{f"ch{channel // 3 * 3 + k}": none for k in range(3)}})
            sig[f"ch{channel}"] = c
        return list(pdos.items())
    if isinstance(m, P.Status):
        n = len(m.positions)
        out = [(P.CAN_STATUS + m.node, {
            "counter": m.tick & 0xFF, "flag_limit": m.flags & 1, "flag_fault": m.flags >> 1 & 1,
            "flag_watchdog": m.flags >> 2 & 1, "flag_following": m.flags >> 3 & 1,
            "flag_estop": m.flags >> 4 & 1, "reserved": 0, "state": m.state, "channels": n, "rejected": m.rejected,
            "seq_gaps": m.seq_gaps})]
        for pdo in range((n + 2) // 3):
            out.append((P.CAN_POSITION + 0x100 * pdo + m.node, {"counter": m.tick & 0xF, **{
                f"ch{3 * pdo + k}": m.positions[3 * pdo + k] if 3 * pdo + k < n else none
                for k in range(3)}}))
        return out
    assert isinstance(m, P.Config)
    cid = P.CAN_CONFIG + m.node
    out = [(cid, {"param": 1, "reserved": 0, "begin_channel": 255, "tick_period_us": m.tick_period_us}),
           (cid, {"param": 2, "reserved": 0, "watchdog_channel": 255, "watchdog_ticks": m.watchdog_ticks})]
    for c in m.channels:
        out += [(cid, {"param": 16, "reserved": 0, "min_channel": c.channel, "min_counts": c.min_counts}),
                (cid, {"param": 17, "reserved": 0, "max_channel": c.channel, "max_counts": c.max_counts}),
                (cid, {"param": 18, "reserved": 0, "speed_channel": c.channel, "max_speed": c.max_speed}),
                (cid, {"param": 19, "reserved": 0, "accel_channel": c.channel, "max_accel": c.max_accel})]
    return out + [(cid, {"param": 127, "reserved": 0, "channels": len(m.channels), "seq": m.seq})]


def test_dbc_and_codec_agree():
    db = cantools.database.load_file(str(DBC))
    assert len(db.messages) == 3 + 12 * DBC_NODES
    rng = np.random.default_rng(SEED + 6)
    seen = set()
    for _ in range(1500):
        m = random_message(rng, can=True)
        if isinstance(m, P.Loudness):
            m = P.Loudness(m.node, m.frame, min(m.value, 1e6), m.bands)
        frames = P.encode_can(m)
        expected = expected_signals(m, frames)
        assert [i for i, _ in frames] == [i for i, _ in expected]
        for (can_id, data), (_, signals) in zip(frames, expected):
            msg = db.get_message_by_frame_id(can_id)
            assert msg.length == len(data), msg.name
            assert db.decode_message(can_id, data, decode_choices=False) == signals, msg.name
            assert db.encode_message(can_id, signals) == data, msg.name
            seen.add(msg.name.split("_N")[0])
    assert seen == {"SYNC", "ESTOP", "ESTOP_RELEASE", "SETPOINT_A", "SETPOINT_B", "SETPOINT_C",
                    "STATUS", "POSITION_A", "POSITION_B", "POSITION_C", "CONFIG", "LOUDNESS",
                    "LOUDNESS_BANDS", "HEARTBEAT", "NACK"}


def test_dbc_bounds_ranges_and_comments_every_message():
    db = cantools.database.load_file(str(DBC))
    assert all(m.comment for m in db.messages)
    n = DBC_NODES
    bounds = {(f"SETPOINT_C_N{n}", "ch8"): (-P.CAN_COUNTS_MAX, P.CAN_COUNTS_MAX),
              (f"POSITION_A_N{n}", "ch0"): (-P.CAN_COUNTS_MAX, P.CAN_COUNTS_MAX),
              (f"STATUS_N{n}", "channels"): (0, P.CAN_CHANNELS), (f"CONFIG_N{n}", "channels"): (0, P.CAN_CHANNELS),
              (f"CONFIG_N{n}", "begin_channel"): (255, 255), (f"CONFIG_N{n}", "watchdog_ticks"): (1, 65535),
              (f"CONFIG_N{n}", "min_channel"): (0, P.CAN_CHANNELS - 1),
              (f"LOUDNESS_BANDS_N{n}", "bands"): (1, P.CAN_BANDS_MAX)}
    for (message, name), (lo, hi) in bounds.items():
        sig = db.get_message_by_name(message).get_signal_by_name(name)
        assert (sig.minimum, sig.maximum) == (lo, hi), (message, name)
    for message, start in ((f"STATUS_N{n}", 13), (f"CONFIG_N{n}", 16)):     # [0|0] reads as no range
        sig = db.get_message_by_name(message).get_signal_by_name("reserved")
        assert sig.start == start and "Reserved" in sig.comment, message
    status = db.get_message_by_name(f"STATUS_N{n}")
    assert db.decode_message(status.frame_id, bytes.fromhex("0520050000000000"))["reserved"] == 1


def test_spec_quotes_the_bus_budget():
    budget = runpy.run_path(str(ROOT / "firmware_protocol" / "tools" / "bus_budget.py"))
    spec = (ROOT / "firmware_protocol" / "SPEC.md").read_text()
    assert budget["table"]().strip() in spec
    assert budget["can_bits"](8) == 135 and budget["can_bits"](1) == 65    # worst-case stuffed frames
