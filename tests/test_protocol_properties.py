"""Properties of the receivers over many random inputs (fixed seeds), so
that a decoder that accepts what it should refuse fails here: node firmware
may call the COBS decoder and the CAN receiver directly, without the
deframer in front.

* every input the COBS decoder accepts is the encoding of what it decoded
  (one encoding per block: SPEC.md 3.1), and every input holding a 0x00 is
  refused;
* every serial frame the decoder accepts is what the encoder makes of the
  decoded message, byte for byte;
* every message the CAN receiver gives is made, by the encoder, of the very
  frames it was given (the last write of each CONFIG parameter)."""
from __future__ import annotations

import numpy as np
import pytest

from marionette import _protocol as _p
from marionette import protocol as P
from test_protocol import random_message

SEED = 20261202
CASES = 20000


def _mutate(rng, data: bytes) -> bytes:
    """data, or data changed in one of the ways a line or a bad encoder changes it."""
    b = bytearray(data)
    kind = int(rng.integers(8))
    if kind == 0 or not b:
        return bytes(b)
    at = int(rng.integers(len(b)))
    if kind == 1:
        b[at] = int(rng.integers(256))
    elif kind == 2:
        b[at] = 0                                   # a zero anywhere: inside a run, or a code byte
    elif kind == 3:
        b.insert(at, 0)
    elif kind == 4:
        del b[at:]
    elif kind == 5:
        b += bytes(rng.integers(0, 256, int(rng.integers(1, 4))).astype(np.uint8))
    elif kind == 6:
        b[at] ^= 1 << int(rng.integers(8))
    elif len(b) > 255 and b[0] == 0xFF and b[-1] == 1:
        del b[-1]                                   # the optimised COBS's ff <254 bytes>
    return bytes(b)


def _cobs_input(rng) -> bytes:
    n = int(rng.choice([0, 1, 2, 253, 254, 255, 508, int(rng.integers(0, 600))]))
    data = rng.integers(0, 256 if rng.random() < 0.5 else 3, n).astype(np.uint8).tobytes()
    if rng.random() < 0.3:
        data = data.replace(b"\0", b"\1")           # long runs: 0xFF code bytes
    return _mutate(rng, P.cobs_encode(data))


def test_cobs_decoder_accepts_only_canonical_encodings_without_zero():
    rng = np.random.default_rng(SEED)
    accepted = refused_zero = 0
    for case in range(CASES):
        wire = _cobs_input(rng)
        try:
            data = P.cobs_decode(wire)
        except ValueError:
            refused_zero += b"\0" in wire
            continue
        assert b"\0" not in wire, (case, wire.hex())
        assert P.cobs_encode(data) == wire, (case, wire.hex())
        accepted += 1
    assert accepted > CASES // 4 and refused_zero > CASES // 10      # both sides were tried


def test_cobs_decoder_refuses_every_zero_and_the_optimised_ending():
    for code in (2, 5, 0xFF):
        run = bytes(range(1, code))
        for at in range(len(run)):              # a 0x00 inside the data run
            bad = bytes([code]) + run[:at] + b"\0" + run[at + 1:] + b"\x01"
            with pytest.raises(ValueError):
                P.cobs_decode(bad)
    body = bytes(range(1, 255))                 # 254 bytes without a zero
    assert P.cobs_encode(body) == b"\xff" + body + b"\x01"
    with pytest.raises(ValueError):
        P.cobs_decode(b"\xff" + body)           # SPEC.md 3.1: the final 01 is required
    with pytest.raises(ValueError):
        P.cobs_decode(b"")                      # the encoding of nothing is 01
    assert P.cobs_decode(b"\x01") == b""


def _reseal(body: bytes) -> bytes:
    """The body with its CRC made good again, so the content checks are reached."""
    if len(body) < 5:
        return body
    return body[:-4] + P.crc32c(body[:-4]).to_bytes(4, "little")


def test_every_accepted_serial_frame_is_its_message_re_encoded():
    rng = np.random.default_rng(SEED + 1)
    accepted = 0
    for case in range(CASES // 2):
        body = P.encode_body(random_message(rng))
        if rng.random() < 0.5:
            body = _reseal(_mutate(rng, body))
        wire = _mutate(rng, P.cobs_encode(body)) if rng.random() < 0.5 else P.cobs_encode(body)
        try:
            message = P.decode_serial(wire)
        except P.ProtocolError:
            continue
        # a mutation may have added the 0x00 that decode_serial takes as optional
        assert P.encode_serial(message) == wire.removesuffix(b"\0") + b"\0", (case, wire.hex())
        accepted += 1
    assert accepted > CASES // 8


# -- CAN --------------------------------------------------------------------

def _can_frames(rng, decoder_tick: int) -> list:
    """Frames of a random message (a STATUS's in any order), some changed."""
    m = random_message(rng, can=True)
    if isinstance(m, P.Setpoints):                  # of the last SYNC, mostly
        m = P.Setpoints(decoder_tick if rng.random() < 0.8 else m.tick, m.entries)
    frames = list(P.encode_can(m))
    if isinstance(m, P.Status):
        frames = [frames[i] for i in rng.permutation(len(frames))]
    out = []
    for can_id, data in frames:
        r = rng.random()
        if r < 0.08:
            continue                                # lost
        if r < 0.12:
            out.append((can_id, data))              # repeated
        if r < 0.3:
            data = bytearray(data)
            data[int(rng.integers(len(data)))] ^= 1 << int(rng.integers(8))
            data = bytes(data)
        elif r < 0.33:
            data = data + b"\0" if len(data) < 8 else data[:-1]
        elif r < 0.36:
            can_id = int(rng.integers(0x800))
        out.append((can_id, data))
    return out


def test_every_message_the_can_receiver_gives_is_made_of_its_frames():
    rng = np.random.default_rng(SEED + 2)
    rx = _p.CanReceiver()
    last = {}           # id -> the last frame taken (not refused) with that id
    config = {}         # node -> {(param, channel): frame} since the node's BEGIN
    kinds = {}
    for case in range(CASES // 4):
        tick = int(rng.integers(0, 2**32))
        assert rx.feed(P.CAN_SYNC, bytes([tick & 0xFF]))[0] == 1
        for can_id, data in _can_frames(rng, rx.tick):
            status, raw = rx.feed(can_id, data)
            if status < 0:
                continue
            last[can_id] = data
            node = can_id & 0x7F
            if can_id & 0x780 == P.CAN_CONFIG:
                if data[0] == 0x01:
                    config[node] = {}
                config.setdefault(node, {})[data[0], data[1] if data[0] != 0x7F else 0] = data
            if status == 0:
                continue
            message = P._message(raw)
            kinds[type(message).__name__] = kinds.get(type(message).__name__, 0) + 1
            frames = P.encode_can(message)
            if isinstance(message, P.Config):
                held = config.pop(node)
                assert all(held[d[0], d[1] if d[0] != 0x7F else 0] == d for _, d in frames), case
                assert len(frames) == len(held), case
            elif isinstance(message, P.Status):
                assert all(last[i] == d for i, d in frames), case
            elif isinstance(message, P.Loudness) and message.bands is not None:
                (bands_id, bands), loudness = frames                # the node's last bands frame
                assert last[bands_id] == bands and loudness == (can_id, data), case
            else:
                assert frames == [(can_id, data)], (case, hex(can_id), data.hex())
    assert set(kinds) == {"Sync", "Setpoints", "Estop", "EstopRelease", "Config", "Status",
                          "Heartbeat", "Loudness", "Nack"}, kinds
