"""The servo protocol, version 1 (firmware_protocol/SPEC.md), for Python.

One implementation: every byte is made and read by the C codec in
firmware_protocol/ (through marionette._protocol); this module only turns
its tuples into readable, frozen dataclasses.

Messages (all integers; counts are device counts, int32)::

    Sync(tick, poll=BROADCAST)                 host: a tick begins; `poll` answers (0xFF: every node)
    Setpoints(tick, entries)                   host: ((node, channel, counts), ...) of one tick
    Estop(node=BROADCAST, seq=0)               host: latch the e-stop, brake to rest
    EstopRelease(node=BROADCAST, seq=0)        host: release the latch
    Config(node, channels=(), watchdog_ticks=5, tick_period_us=20000, seq=0)
        ChannelConfig(channel, min_counts, max_counts, max_speed, max_accel)   [counts], [counts/s], [counts/s^2]
    Status(node, tick, flags=0, state=STATE_OPERATIONAL, rejected=0, seq_gaps=0, positions=())
    Heartbeat(node, state, seq=0)
    Loudness(node, frame, value, bands=None)   value is a float32 on the wire (rounded here); bands:
                                               band levels [full scale], lowest first, None from a
                                               node that measures the loudness alone; a byte each
                                               on the wire (band_code: 0.5 dB steps, rounded here)
    Nack(node, reason, ref_type=0, ref_seq=0, flags=0, seq=0)   reason 0 (REASON_ACCEPTED) acknowledges a CONFIG
    Refused(reason, type, node, seq)           not a message: a frame whose CRC was good but whose content
                                               was refused (what a node answers with a Nack)

Serial (COBS frames, each ended by 0x00)::

    encode_serial(message) -> bytes            Setpoints with more than SETPOINT_MAX entries give several frames
    decode_serial(frame) -> message            one frame, with or without its 0x00; raises ProtocolError
    encode_body(message) -> bytes; decode_body(body) -> message      the frame before COBS
    Deframer().feed(data, refusals=False) -> [message, ...]          any chunks of a byte stream
        .counters -> dict (bytes, frames_ok, crc_errors, cobs_errors, too_long, too_short,
                           decode_errors, garbage_bytes); .rejected -> int; .frames_ok -> int

CAN (11-bit identifiers, CANopen-like; firmware_protocol/marionette.dbc)::

    encode_can(message) -> [(can_id, data), ...]
    CanDecoder().feed(can_id, data, refusals=False) -> [message] or []   joins STATUS and CONFIG
        frames and a LOUDNESS's bands, unwraps the SYNC counter (.tick); .counters; .rejected
    decode_can_frames([(can_id, data), ...]) -> [message, ...]      with a fresh CanDecoder
    can_records(buf) -> [(can_id, data), ...]   the engine's CAN ring records (ext/mar_sink.h)
    can_record(can_id, data) -> bytes           one such record

On CAN a tick is carried modulo 256 (SYNC, STATUS) or 16 (setpoint PDOs):
a CanDecoder gives the tick unwrapped from the SYNCs it has seen, so feed
it the host's own SYNC frames too when decoding statuses on the host.
ESTOP, ESTOP_RELEASE, HEARTBEAT and NACK carry no seq on CAN (decoded 0).

Helpers: band_code(level) -> the byte of a band level; band_level(code) -> the level
[full scale]; node_config(figure, node, watchdog_ticks=5) -> Config from a
FigureConfig; config_reason(config) -> the reason a node answers it with;
crc32c(data), cobs_encode(data), cobs_decode(data); fuzz(seed, frames) ->
dict (the C fuzzer behind ``marionette bench fuzz``).

Errors: ProtocolError (a ValueError) with .code, a negative E_* status.

    from marionette import protocol
    wire = protocol.encode_serial(protocol.Sync(tick=12))
    deframer = protocol.Deframer()
    for message in deframer.feed(wire):
        print(message)                       # Sync(tick=12, poll=255)
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from marionette import _protocol as _p
from marionette.errors import ArgumentError, MarionetteError

VERSION = _p.VERSION
BROADCAST = _p.BROADCAST                # node address of "every node"
FRAME_MAX = _p.FRAME_MAX                # largest frame body [bytes]
WIRE_MAX = _p.WIRE_MAX                  # largest frame on the wire, with its 0x00 [bytes]
SETPOINT_MAX = _p.SETPOINT_MAX          # setpoints in one SETPOINT frame
STATUS_MAX = _p.STATUS_MAX              # positions in one STATUS
CONFIG_MAX = _p.CONFIG_MAX              # channels in one CONFIG
BANDS_MAX = _p.BANDS_MAX                # bands in one LOUDNESS (serial)
CAN_BANDS_MAX = _p.CAN_BANDS_MAX        # bands in one LOUDNESS on CAN
BAND_SILENT = _p.BAND_SILENT            # the code of a band below the lowest level, or silent

# message types (the frame's type byte; bit 7: sent by a node)
SYNC = _p.MSG_SYNC
SETPOINT = _p.MSG_SETPOINT
ESTOP = _p.MSG_ESTOP
ESTOP_RELEASE = _p.MSG_ESTOP_RELEASE
CONFIG = _p.MSG_CONFIG
STATUS = _p.MSG_STATUS
HEARTBEAT = _p.MSG_HEARTBEAT
LOUDNESS = _p.MSG_LOUDNESS
NACK = _p.MSG_NACK
FROM_NODE = 0x80             # type bit 7: sent by a node
TYPE_NAMES = {SYNC: "SYNC", SETPOINT: "SETPOINT", ESTOP: "ESTOP", ESTOP_RELEASE: "ESTOP_RELEASE",
              CONFIG: "CONFIG", STATUS: "STATUS", HEARTBEAT: "HEARTBEAT", LOUDNESS: "LOUDNESS",
              NACK: "NACK"}

# STATUS and NACK flags
FLAG_LIMIT = 0x01           # a setpoint was clamped to the node's limits since the last STATUS
FLAG_FAULT = 0x02           # the drive reports a fault
FLAG_WATCHDOG = 0x04        # no setpoint within the watchdog time: braking or at rest
FLAG_FOLLOWING = 0x08       # following error above the node's threshold
FLAG_ESTOP = 0x10           # e-stop latched

# node states (CANopen NMT numbers)
STATE_BOOT = 0x00
STATE_STOPPED = 0x04        # e-stop latched
STATE_OPERATIONAL = 0x05    # following setpoints
STATE_PRE_OPERATIONAL = 0x7F    # holding: no setpoint yet, or the watchdog tripped

# NACK reasons
REASON_ACCEPTED = 0
REASON_BAD_VERSION = 1
REASON_BAD_TYPE = 2
REASON_BAD_LENGTH = 3
REASON_BAD_VALUE = 4
REASON_BAD_CHANNEL = 5
REASON_BAD_CONFIG = 6
REASON_ESTOP_LATCHED = 7
REASON_STALE = 8
REASON_CONFIG_INCOMPLETE = 9
REASON_DRIVE_FAULT = 0x1000
REASONS = {0: "accepted", 1: "bad version", 2: "bad type", 3: "bad length", 4: "bad value",
           5: "bad channel", 6: "bad config", 7: "e-stop latched", 8: "stale", 9: "config incomplete",
           0x1000: "drive fault"}

# codec status codes
E_SHORT, E_CRC, E_VERSION, E_TYPE = _p.E_SHORT, _p.E_CRC, _p.E_VERSION, _p.E_TYPE
E_LENGTH, E_VALUE, E_COBS, E_TOOLONG = _p.E_LENGTH, _p.E_VALUE, _p.E_COBS, _p.E_TOOLONG
E_RANGE, E_STALE, E_INCOMPLETE, E_ID = _p.E_RANGE, _p.E_STALE, _p.E_INCOMPLETE, _p.E_ID
ERRORS = {E_SHORT: "too short", E_CRC: "CRC mismatch", E_VERSION: "not version 1",
          E_TYPE: "unknown message type", E_LENGTH: "wrong length for its type",
          E_VALUE: "a field holds a value the protocol does not allow", E_COBS: "invalid COBS",
          E_TOOLONG: "too long", E_RANGE: "does not fit (too many entries or a value out of range)",
          E_STALE: "setpoint PDO without its SYNC", E_INCOMPLETE: "configuration incomplete",
          E_ID: "CAN identifier outside the mapping"}

# CAN identifiers (+ node where the name says so)
CAN_ESTOP = _p.CAN_ESTOP                # 0x001
CAN_ESTOP_RELEASE = _p.CAN_ESTOP_RELEASE    # 0x002
CAN_SYNC = _p.CAN_SYNC                  # 0x080
CAN_EMCY = _p.CAN_EMCY                  # 0x080 + node: NACK
CAN_STATUS = _p.CAN_STATUS              # 0x180 + node
CAN_SETPOINT = _p.CAN_SETPOINT          # 0x200 + 0x100 * pdo + node, pdo 0..2 (channels 3*pdo ..)
CAN_POSITION = _p.CAN_POSITION          # 0x280 + 0x100 * pdo + node
CAN_BANDS = _p.CAN_BANDS                # 0x580 + node: LOUDNESS bands, just before their LOUDNESS
CAN_CONFIG = _p.CAN_CONFIG              # 0x600 + node
CAN_LOUDNESS = _p.CAN_LOUDNESS          # 0x680 + node
CAN_HEARTBEAT = _p.CAN_HEARTBEAT        # 0x700 + node
CAN_NODE_MAX = _p.CAN_NODE_MAX          # nodes 1..127
CAN_CHANNELS = _p.CAN_CHANNELS          # channels 0..8
CAN_COUNTS_MAX = _p.CAN_COUNTS_MAX      # int20: +-524287 counts
CAN_RECORD_BYTES = 16                   # ext/mar_sink.h: struct can_frame layout
_RECORD = struct.Struct("<IB3x8s")


class ProtocolError(MarionetteError, ValueError):
    """A frame that could not be decoded, or a message that cannot be encoded."""

    def __init__(self, code: int, text: str):
        super().__init__(text)
        self.code = code


def _entries(entries) -> tuple:
    return tuple((int(n), int(c), int(v)) for n, c, v in entries)


def _float32(value) -> float:
    try:
        return struct.unpack("<f", struct.pack("<f", value))[0]
    except (OverflowError, struct.error):
        return float(value)         # out of float32 range: the encoder refuses it


def band_code(level: float) -> int:
    """The byte that carries a band level (linear [full scale], finite,
    >= 0): 0.5 dB steps down from +6 dB re full scale (code 0, also for
    louder levels) to -121 dB (254); BAND_SILENT below that and for 0."""
    level = float(level)
    if not 0.0 <= level < math.inf:
        raise ProtocolError(E_VALUE, f"band level {level!r}: must be finite and >= 0")
    return _p.band_code(20.0 * math.log10(level) if level > 0 else -math.inf)


def band_level(code: int) -> float:
    """The band level a code stands for [full scale]; 0.0 for BAND_SILENT."""
    db = _p.band_db(code)
    return 0.0 if db == -math.inf else 10.0 ** (db / 20.0)


@dataclass(frozen=True)
class Sync:
    tick: int                       # tick counter (the frame's seq)
    poll: int = BROADCAST           # node that answers with STATUS; BROADCAST: every node

    def _raw(self):
        return (SYNC, BROADCAST, self.tick, (self.poll,))


@dataclass(frozen=True)
class Setpoints:
    tick: int
    entries: tuple = ()             # ((node, channel, counts), ...)

    def __post_init__(self):
        object.__setattr__(self, "entries", _entries(self.entries))

    def _raw(self):
        return (SETPOINT, BROADCAST, self.tick, (self.entries,))


@dataclass(frozen=True)
class Estop:
    node: int = BROADCAST
    seq: int = 0

    def _raw(self):
        return (ESTOP, self.node, self.seq, ())


@dataclass(frozen=True)
class EstopRelease:
    node: int = BROADCAST
    seq: int = 0

    def _raw(self):
        return (ESTOP_RELEASE, self.node, self.seq, ())


@dataclass(frozen=True)
class ChannelConfig:
    channel: int
    min_counts: int                 # position limits [counts]
    max_counts: int
    max_speed: int                  # [counts/s]
    max_accel: int                  # [counts/s^2]


@dataclass(frozen=True)
class Config:
    node: int
    channels: tuple = ()            # (ChannelConfig, ...); channels not listed keep theirs
    watchdog_ticks: int = 5         # [ticks] without a setpoint before the node brakes
    tick_period_us: int = 20000     # nominal tick [us], the watchdog's time base
    seq: int = 0

    def __post_init__(self):
        object.__setattr__(self, "channels", tuple(
            c if isinstance(c, ChannelConfig) else ChannelConfig(*c) for c in self.channels))

    def _raw(self):
        return (CONFIG, self.node, self.seq, (self.tick_period_us, self.watchdog_ticks, tuple(
            (c.channel, c.min_counts, c.max_counts, c.max_speed, c.max_accel) for c in self.channels)))


@dataclass(frozen=True)
class Status:
    node: int
    tick: int                       # the SYNC it answers
    flags: int = 0                  # FLAG_*
    state: int = STATE_OPERATIONAL  # STATE_*
    rejected: int = 0               # frames the node refused since it started, mod 2^16
    seq_gaps: int = 0               # ticks it got no setpoint for, mod 2^16
    positions: tuple = ()           # actual positions of channels 0.. [counts]

    def __post_init__(self):
        object.__setattr__(self, "positions", tuple(int(p) for p in self.positions))

    def _raw(self):
        return (STATUS, self.node, self.tick,
                (self.flags, self.state, self.rejected, self.seq_gaps, self.positions))


@dataclass(frozen=True)
class Heartbeat:
    node: int
    state: int                      # STATE_*
    seq: int = 0

    def _raw(self):
        return (HEARTBEAT, self.node, self.seq, (self.state,))


@dataclass(frozen=True)
class Loudness:
    node: int
    frame: int                      # the node's audio frame counter (20 ms frames)
    value: float                    # loudness, >= 0, in the show's loudness unit; float32
    bands: tuple | None = None      # band levels [full scale], lowest first; None: loudness alone

    def __post_init__(self):
        object.__setattr__(self, "value", _float32(self.value))
        if self.bands is not None:
            bands = tuple(float(b) for b in self.bands)
            if all(0.0 <= b < math.inf for b in bands):     # else the encoder names the bad one
                bands = tuple(band_level(band_code(b)) for b in bands)
            object.__setattr__(self, "bands", bands or None)

    def _raw(self):
        codes = () if self.bands is None else tuple(band_code(b) for b in self.bands)
        return (LOUDNESS, self.node, self.frame, (self.value, codes))


@dataclass(frozen=True)
class Nack:
    node: int
    reason: int                     # REASON_*; 0 acknowledges a CONFIG
    ref_type: int = 0               # type of the frame it answers
    ref_seq: int = 0                # and that frame's seq
    flags: int = 0                  # the node's FLAG_* now
    seq: int = 0

    def describe(self) -> str:
        what = TYPE_NAMES.get(self.ref_type, f"type 0x{self.ref_type:02x}")
        return f"{REASONS.get(self.reason, f'reason {self.reason}')} ({what} seq {self.ref_seq})"

    def _raw(self):
        return (NACK, self.node, self.seq, (self.reason, self.flags, self.ref_type, self.ref_seq))


@dataclass(frozen=True)
class Refused:
    """A frame with a good CRC whose content was refused (Deframer.feed(refusals=True))."""
    reason: int                     # REASON_* a node answers it with
    type: int
    node: int
    seq: int


Message = Sync | Setpoints | Estop | EstopRelease | Config | Status | Heartbeat | Loudness | Nack


def _message(raw) -> Message:
    kind, node, seq, p = raw
    if kind == SYNC:
        return Sync(seq, p[0])
    if kind == SETPOINT:
        return Setpoints(seq, p[0])
    if kind == ESTOP:
        return Estop(node, seq)
    if kind == ESTOP_RELEASE:
        return EstopRelease(node, seq)
    if kind == CONFIG:
        return Config(node, tuple(ChannelConfig(*c) for c in p[2]), p[1], p[0], seq)
    if kind == STATUS:
        return Status(node, seq, *p)
    if kind == HEARTBEAT:
        return Heartbeat(node, p[0], seq)
    if kind == LOUDNESS:
        return Loudness(node, seq, p[0], tuple(band_level(c) for c in p[1]) or None)
    return Nack(node, p[0], p[2], p[3], p[1], seq)


def _raw(message):
    try:
        return message._raw()
    except AttributeError:
        raise TypeError(f"not a protocol message: {message!r}") from None


def _check(result, message):
    if isinstance(result, int):
        raise ProtocolError(result, f"cannot encode {message!r}: {ERRORS.get(result, result)}")
    return result


def _encode(fn, message):
    try:
        return _check(fn(_raw(message)), message)
    except ProtocolError:
        raise
    except ValueError as exc:       # a field outside its C type
        raise ProtocolError(E_RANGE, f"cannot encode {message!r}: {exc}") from None


def _decoded(status, raw, what):
    if status < 0:
        raise ProtocolError(status, f"{what}: {ERRORS.get(status, status)}")
    return _message(raw)


# -- serial -------------------------------------------------------------

def encode_serial(message: Message) -> bytes:
    """The COBS frame(s) of a message, each ended by 0x00."""
    if isinstance(message, Setpoints) and len(message.entries) > SETPOINT_MAX:
        try:
            return _check(_p.encode_setpoints(message.tick, message.entries), message)
        except ProtocolError:
            raise
        except ValueError as exc:
            raise ProtocolError(E_RANGE, f"cannot encode {message!r}: {exc}") from None
    return _encode(_p.encode_frame, message)


def decode_serial(frame: bytes) -> Message:
    """The message of one COBS frame (its 0x00 may be there or not)."""
    return _decoded(*_p.decode_frame(bytes(frame)), "serial frame")


def encode_body(message: Message) -> bytes:
    """The frame body (header, payload, CRC-32C) before COBS."""
    return _encode(_p.encode_body, message)


def decode_body(body: bytes) -> Message:
    return _decoded(*_p.decode_body(bytes(body)), "frame body")


class Deframer:
    """Receives a serial byte stream in chunks of any size.

    feed() returns the messages the chunk completed; frames that fail
    (garbage, CRC, overlong) are counted and skipped, and the next 0x00
    puts the deframer in step again."""

    def __init__(self):
        self._d = _p.Deframer()

    def feed(self, data: bytes, refusals: bool = False) -> list:
        """Messages completed by data; with refusals, also Refused items for
        frames whose CRC was good but whose content was refused."""
        out = []
        for status, raw in self._d.feed(bytes(data), refusals):
            if status == 0:
                out.append(_message(raw))
            else:
                out.append(Refused(_p.reason_of(status), raw[0], raw[1], raw[2]))
        return out

    @property
    def counters(self) -> dict:
        """bytes, frames_ok, crc_errors, cobs_errors, too_long, too_short,
        decode_errors, garbage_bytes (uint32, wrapping)."""
        return self._d.counters

    @property
    def frames_ok(self) -> int:
        return self._d.counters["frames_ok"]

    @property
    def rejected(self) -> int:
        """Frames refused for any reason."""
        c = self._d.counters
        return (c["crc_errors"] + c["cobs_errors"] + c["too_long"] + c["too_short"]
                + c["decode_errors"])


# -- CAN ----------------------------------------------------------------

def encode_can(message: Message) -> list[tuple[int, bytes]]:
    """The CAN frames (identifier, data) of a message."""
    if isinstance(message, Setpoints) and len(message.entries) > SETPOINT_MAX:
        out = []
        for at in range(0, len(message.entries), SETPOINT_MAX):
            out += encode_can(Setpoints(message.tick, message.entries[at:at + SETPOINT_MAX]))
        return out
    return _encode(_p.can_encode, message)


class CanDecoder:
    """Receives CAN frames one by one: unwraps the SYNC counter into a tick,
    gives setpoint PDOs that tick (refusing stale ones), joins a STATUS's
    header and position frames and a CONFIG's parameter frames."""

    def __init__(self):
        self._rx = _p.CanReceiver()
        self.frames = 0             # frames fed
        self.messages = 0           # messages given
        self.errors: dict[int, int] = {}    # status code -> frames refused

    def feed(self, can_id: int, data: bytes, refusals: bool = False) -> list:
        """[message] when the frame completed one, else []; with refusals,
        [Refused] for a frame of this protocol's identifiers that was
        refused (what a node answers with a NACK; seq is APPLY's value)."""
        self.frames += 1
        status, raw = self._rx.feed(int(can_id), bytes(data))
        if status == 1:
            self.messages += 1
            return [_message(raw)]
        if status < 0:
            self.errors[status] = self.errors.get(status, 0) + 1
            if refusals and status != E_ID:
                return [_can_refused(status, int(can_id), bytes(data))]
        return []

    @property
    def tick(self) -> int | None:
        """The unwrapped tick of the last SYNC seen, None before the first."""
        return self._rx.tick

    @property
    def rejected(self) -> int:
        return sum(self.errors.values())

    @property
    def counters(self) -> dict:
        return {"frames": self.frames, "messages": self.messages, "rejected": self.rejected,
                "stale": self.errors.get(E_STALE, 0)}


# function code (identifier & 0x780) -> the message type its frames carry
_CAN_TYPES = {CAN_EMCY: NACK, CAN_STATUS: STATUS, CAN_POSITION: STATUS, CAN_POSITION + 0x100: STATUS,
              CAN_POSITION + 0x200: STATUS, CAN_SETPOINT: SETPOINT, CAN_SETPOINT + 0x100: SETPOINT,
              CAN_SETPOINT + 0x200: SETPOINT, CAN_CONFIG: CONFIG, CAN_BANDS: LOUDNESS,
              CAN_LOUDNESS: LOUDNESS, CAN_HEARTBEAT: HEARTBEAT}


def _can_refused(status: int, can_id: int, data: bytes) -> Refused:
    """Type, addressee and seq of a refused CAN frame, as a serial header would give them."""
    reason = _p.reason_of(status)
    if can_id in (CAN_ESTOP, CAN_ESTOP_RELEASE):
        node = data[0] if len(data) == 1 else BROADCAST
        return Refused(reason, ESTOP if can_id == CAN_ESTOP else ESTOP_RELEASE, node, 0)
    if can_id == CAN_SYNC:
        return Refused(reason, SYNC, BROADCAST, 0)
    kind = _CAN_TYPES.get(can_id & 0x780, 0)
    seq = int.from_bytes(data[4:8], "little") if kind == CONFIG and data[:1] == b"\x7f" else 0
    return Refused(reason, kind, can_id & 0x7F, seq)


def decode_can_frames(frames) -> list:
    """The messages a fresh CanDecoder makes of [(can_id, data), ...]."""
    decoder = CanDecoder()
    return [m for can_id, data in frames for m in decoder.feed(can_id, data)]


def can_records(buf: bytes) -> list[tuple[int, bytes]]:
    """(can_id, data) of each CAN record the engine's ring holds (ext/mar_sink.h)."""
    if len(buf) % CAN_RECORD_BYTES:
        raise ProtocolError(E_LENGTH, f"{len(buf)} bytes is not a whole number of "
                                      f"{CAN_RECORD_BYTES}-byte CAN records")
    return [(can_id, data[:dlc]) for can_id, dlc, data in _RECORD.iter_unpack(buf)]


def can_record(can_id: int, data: bytes) -> bytes:
    """One record in the layout of the engine's ring (struct can_frame)."""
    return _RECORD.pack(can_id, len(data), bytes(data).ljust(8, b"\0"))


# -- helpers ------------------------------------------------------------

def _clip(value: float, lo: int, hi: int) -> int:
    return int(min(max(round(value), lo), hi))


def node_config(figure, node: int, watchdog_ticks: int = 5, seq: int = 0) -> Config:
    """The CONFIG for one node of a FigureConfig: per channel the limits in
    counts (offset + scale * min/max, in order), top speed and acceleration
    in counts/s and counts/s^2 (|scale| times the axis's), and the tick."""
    channels = []
    for a in sorted((a for a in figure.axes if a.node == node), key=lambda a: a.channel):
        lo, hi = sorted((a.offset + a.scale * a.min, a.offset + a.scale * a.max))
        channels.append(ChannelConfig(a.channel, _clip(lo, -2**31, 2**31 - 1), _clip(hi, -2**31, 2**31 - 1),
                                      _clip(abs(a.scale) * a.max_speed, 1, 2**32 - 1),
                                      _clip(abs(a.scale) * a.max_accel, 1, 2**32 - 1)))
    if not channels:
        raise ArgumentError(f"figure {figure.name!r} has no axis on node {node}")
    return Config(node, tuple(channels), watchdog_ticks, round(figure.tick_period * 1e6), seq)


def config_reason(config: Config) -> int:
    """What a node answers this CONFIG with: REASON_ACCEPTED or REASON_BAD_CONFIG."""
    return _p.config_reason(_raw(config))


def crc32c(data: bytes) -> int:
    return _p.crc32c(bytes(data))


def cobs_encode(data: bytes) -> bytes:
    return _p.cobs_encode(bytes(data))


def cobs_decode(data: bytes) -> bytes:
    return _p.cobs_decode(bytes(data))


def fuzz(seed: int, frames: int) -> dict:
    """The C fuzzer (firmware_protocol/mar_fuzz.h), run without the GIL."""
    return _p.fuzz(seed, frames)
