# cython: language_level=3, boundscheck=False, wraparound=False
"""Binding of the protocol codec (firmware_protocol/, version 1).

Messages cross this boundary as plain tuples ``(type, node, seq, payload)``;
marionette.protocol turns them into dataclasses. payload by type:

    SYNC           (poll,)
    SETPOINT       (entries,)  entries: ((node, channel, counts), ...)
    ESTOP, ESTOP_RELEASE  ()
    CONFIG         (tick_period_us, watchdog_ticks, ((channel, min, max, speed, accel), ...))
    STATUS         (flags, state, rejected, seq_gaps, (position, ...))
    HEARTBEAT      (state,)
    LOUDNESS       (value, codes)  codes: the band codes, () for the loudness alone
    NACK           (reason, flags, ref_type, ref_seq)

Functions return C status codes (negative, MAR_E_*) where decoding may
fail; values that cannot be encoded raise ValueError.
"""
from libc.float cimport FLT_MAX
from libc.stdint cimport int32_t, uint8_t, uint16_t, uint32_t, uint64_t
from libc.string cimport memset

from marionette._cprotocol cimport *
from marionette.errors import ArgumentError

VERSION = MAR_PROTO_VERSION
BROADCAST = MAR_BROADCAST
HEADER_BYTES = MAR_HEADER_BYTES
CRC_BYTES = MAR_CRC_BYTES
FRAME_MAX = MAR_FRAME_MAX
PAYLOAD_MAX = MAR_PAYLOAD_MAX
WIRE_MAX = MAR_WIRE_MAX
SETPOINT_MAX = MAR_SETPOINT_MAX
STATUS_MAX = MAR_STATUS_MAX
CONFIG_MAX = MAR_CONFIG_MAX
CAN_NODE_MAX = MAR_CAN_NODE_MAX
CAN_CHANNELS = MAR_CAN_CHANNELS
CAN_COUNTS_MAX = MAR_CAN_COUNTS_MAX
CAN_COUNTS_NONE = MAR_CAN_COUNTS_NONE
BANDS_MAX = MAR_BANDS_MAX
CAN_BANDS_MAX = MAR_CAN_BANDS_MAX
BAND_SILENT = MAR_BAND_SILENT

MSG_SYNC = MAR_MSG_SYNC
MSG_SETPOINT = MAR_MSG_SETPOINT
MSG_ESTOP = MAR_MSG_ESTOP
MSG_ESTOP_RELEASE = MAR_MSG_ESTOP_RELEASE
MSG_CONFIG = MAR_MSG_CONFIG
MSG_STATUS = MAR_MSG_STATUS
MSG_HEARTBEAT = MAR_MSG_HEARTBEAT
MSG_LOUDNESS = MAR_MSG_LOUDNESS
MSG_NACK = MAR_MSG_NACK

E_SHORT = MAR_E_SHORT
E_CRC = MAR_E_CRC
E_VERSION = MAR_E_VERSION
E_TYPE = MAR_E_TYPE
E_LENGTH = MAR_E_LENGTH
E_VALUE = MAR_E_VALUE
E_COBS = MAR_E_COBS
E_TOOLONG = MAR_E_TOOLONG
E_RANGE = MAR_E_RANGE
E_STALE = MAR_E_STALE
E_INCOMPLETE = MAR_E_INCOMPLETE
E_ID = MAR_E_ID

CAN_ESTOP = MAR_CAN_ESTOP
CAN_ESTOP_RELEASE = MAR_CAN_ESTOP_RELEASE
CAN_SYNC = MAR_CAN_SYNC
CAN_EMCY = MAR_CAN_EMCY
CAN_STATUS = MAR_CAN_STATUS
CAN_SETPOINT = MAR_CAN_SETPOINT
CAN_POSITION = MAR_CAN_POSITION
CAN_CONFIG = MAR_CAN_CONFIG
CAN_BANDS = MAR_CAN_BANDS
CAN_LOUDNESS = MAR_CAN_LOUDNESS
CAN_HEARTBEAT = MAR_CAN_HEARTBEAT


cdef int to_msg(object raw, mar_msg *m) except -1:
    """Fills m from a raw tuple; ValueError for what does not fit its C field."""
    cdef size_t i, n
    memset(m, 0, sizeof(mar_msg))
    try:
        kind, node, seq, payload = raw
        m.type = kind
        m.node = node
        m.seq = seq
        if kind == MAR_MSG_SYNC:
            m.sync.poll = payload[0]
        elif kind == MAR_MSG_SETPOINT:
            entries = payload[0]
            n = len(entries)
            if n > MAR_SETPOINT_MAX:
                raise ArgumentError(f"{n} setpoints in one frame; at most {MAR_SETPOINT_MAX} "
                                    f"(encode_setpoints splits any number)")
            for i in range(n):
                m.setpoint.entry[i].node, m.setpoint.entry[i].channel, m.setpoint.entry[i].counts = entries[i]
            m.setpoint.n = <uint16_t>n
        elif kind == MAR_MSG_CONFIG:
            m.config.tick_period_us, m.config.watchdog_ticks, channels = payload
            n = len(channels)
            if n > MAR_CONFIG_MAX:
                raise ArgumentError(f"{n} channels in one CONFIG; at most {MAR_CONFIG_MAX}")
            for i in range(n):
                c = channels[i]
                m.config.channel[i].channel = c[0]
                m.config.channel[i].min_counts = c[1]
                m.config.channel[i].max_counts = c[2]
                m.config.channel[i].max_speed = c[3]
                m.config.channel[i].max_accel = c[4]
            m.config.n = <uint8_t>n
        elif kind == MAR_MSG_STATUS:
            m.status.flags, m.status.state, m.status.rejected, m.status.seq_gaps, positions = payload
            n = len(positions)
            if n > MAR_STATUS_MAX:
                raise ArgumentError(f"{n} positions in one STATUS; at most {MAR_STATUS_MAX}")
            for i in range(n):
                m.status.position[i] = positions[i]
            m.status.n = <uint8_t>n
        elif kind == MAR_MSG_HEARTBEAT:
            m.heartbeat.state = payload[0]
        elif kind == MAR_MSG_LOUDNESS:
            value = float(payload[0])
            if not (0.0 <= value <= FLT_MAX):
                raise ArgumentError(f"loudness {value!r}: must be finite and >= 0")
            m.loudness.value = <float>value
            codes = payload[1]
            n = len(codes)
            if n > MAR_BANDS_MAX:
                raise ArgumentError(f"{n} bands in one LOUDNESS; at most {MAR_BANDS_MAX}")
            for i in range(n):
                m.loudness.band[i] = codes[i]
            m.loudness.n_bands = <uint8_t>n
        elif kind == MAR_MSG_NACK:
            m.nack.reason, m.nack.flags, m.nack.ref_type, m.nack.ref_seq = payload
    except OverflowError as exc:
        raise ArgumentError(f"a field of message type 0x{raw[0]:02x} is out of its range: {exc}") from None
    return 0


cdef object from_msg(const mar_msg *m):
    cdef size_t i
    cdef int t = m.type
    if t == MAR_MSG_SYNC:
        payload = (m.sync.poll,)
    elif t == MAR_MSG_SETPOINT:
        payload = (tuple([(m.setpoint.entry[i].node, m.setpoint.entry[i].channel,
                           m.setpoint.entry[i].counts) for i in range(m.setpoint.n)]),)
    elif t == MAR_MSG_CONFIG:
        payload = (m.config.tick_period_us, m.config.watchdog_ticks,
                   tuple([(m.config.channel[i].channel, m.config.channel[i].min_counts,
                           m.config.channel[i].max_counts, m.config.channel[i].max_speed,
                           m.config.channel[i].max_accel) for i in range(m.config.n)]))
    elif t == MAR_MSG_STATUS:
        payload = (m.status.flags, m.status.state, m.status.rejected, m.status.seq_gaps,
                   tuple([m.status.position[i] for i in range(m.status.n)]))
    elif t == MAR_MSG_HEARTBEAT:
        payload = (m.heartbeat.state,)
    elif t == MAR_MSG_LOUDNESS:
        payload = (<double>m.loudness.value,
                   tuple([m.loudness.band[i] for i in range(m.loudness.n_bands)]))
    elif t == MAR_MSG_NACK:
        payload = (m.nack.reason, m.nack.flags, m.nack.ref_type, m.nack.ref_seq)
    else:
        payload = ()
    return (m.type, m.node, m.seq, payload)


def crc32c(const uint8_t[::1] data):
    """CRC-32C of the bytes (the frame check)."""
    if data.shape[0] == 0:
        return mar_crc32c(NULL, 0)
    return mar_crc32c(&data[0], data.shape[0])


def cobs_encode(const uint8_t[::1] data):
    """COBS of the bytes, without the 0x00 delimiter."""
    cdef size_t n = data.shape[0]
    out = bytearray(MAR_COBS_MAX(n))
    cdef uint8_t *o = out
    cdef size_t k = mar_cobs_encode(&data[0] if n else NULL, n, o)
    return bytes(out[:k])


def cobs_decode(const uint8_t[::1] data):
    """The bytes a COBS block (without delimiter) stands for; ValueError if invalid."""
    cdef size_t n = data.shape[0]
    out = bytearray(n)
    cdef uint8_t *o = out
    cdef long k = mar_cobs_decode(&data[0], n, o, n) if n else -1
    if k < 0:
        raise ArgumentError("invalid COBS encoding")
    return bytes(out[:k])


def encode_frame(raw):
    """The serial frame (COBS and 0x00) of one message."""
    cdef mar_msg m
    cdef uint8_t wire[MAR_WIRE_MAX]
    to_msg(raw, &m)
    cdef long n = mar_encode_frame(&m, wire, MAR_WIRE_MAX)
    if n < 0:
        return n
    return (<char *>wire)[:n]


def encode_body(raw):
    """The frame body (header, payload, CRC) of one message, before COBS."""
    cdef mar_msg m
    cdef uint8_t body[MAR_FRAME_MAX]
    to_msg(raw, &m)
    cdef long n = mar_encode_body(&m, body, MAR_FRAME_MAX)
    if n < 0:
        return n
    return (<char *>body)[:n]


def encode_setpoints(uint32_t tick, entries):
    """The SETPOINT frames of one tick for any number of (node, channel, counts)."""
    cdef size_t n = len(entries), i
    cdef mar_setpoint_entry e
    buf = bytearray(n * sizeof(mar_setpoint_entry))
    cdef mar_setpoint_entry *es = <mar_setpoint_entry *><uint8_t *>buf if n else NULL
    try:
        for i in range(n):
            es[i].node, es[i].channel, es[i].counts = entries[i]
    except OverflowError as exc:
        raise ArgumentError(f"setpoint entry {i} out of range: {exc}") from None
    out = bytearray(mar_setpoints_wire_max(n))
    cdef uint8_t *o = out
    cdef long k = mar_encode_setpoints(tick, es, n, o, len(out))
    if k < 0:
        return k
    return bytes(out[:k])


def decode_frame(const uint8_t[::1] wire):
    """(status, raw): one serial frame, with or without its 0x00."""
    cdef mar_msg m
    cdef int r = mar_decode_frame(&wire[0], wire.shape[0], &m) if wire.shape[0] else MAR_E_SHORT
    return (r, from_msg(&m) if r == 0 else None)


def decode_body(const uint8_t[::1] body):
    """(status, raw): one frame body (before COBS)."""
    cdef mar_msg m
    cdef int r = mar_decode_body(&body[0], body.shape[0], &m) if body.shape[0] else MAR_E_SHORT
    return (r, from_msg(&m) if r == 0 else None)


def config_reason(raw):
    """The NACK reason a node answers this CONFIG with (0: accepted)."""
    cdef mar_msg m
    to_msg(raw, &m)
    return mar_config_reason(&m)


def band_code(float db):
    """The code of a band level [dB re full scale] (mar_band_code): 0 .. 255,
    or E_VALUE for NaN and +infinity."""
    return mar_band_code(db)


def band_db(uint8_t code):
    """The level of a band code [dB re full scale]; -inf for BAND_SILENT."""
    return mar_band_db(code)


def reason_of(int status):
    """The NACK reason for a decoder status."""
    return mar_reason_of(status)


cdef class Deframer:
    """Streaming receiver of serial frames (mar_deframer)."""
    cdef mar_deframer d
    cdef mar_msg m

    def __cinit__(self):
        mar_deframer_init(&self.d)

    def feed(self, const uint8_t[::1] data, bint refusals=False):
        """[(0, raw)] for each message the bytes complete; with refusals, also
        (status, (type, node, seq, None)) for frames whose CRC was good but
        whose content was refused, in stream order."""
        out = []
        cdef Py_ssize_t i
        cdef int r
        for i in range(data.shape[0]):
            r = mar_deframer_push(&self.d, data[i], &self.m)
            if r == 1:
                out.append((0, from_msg(&self.m)))
            elif refusals and r in (MAR_E_VERSION, MAR_E_TYPE, MAR_E_LENGTH, MAR_E_VALUE):
                out.append((r, (self.m.type, self.m.node, self.m.seq, None)))
        return out

    @property
    def counters(self):
        return dict(bytes=self.d.bytes, frames_ok=self.d.frames_ok, crc_errors=self.d.crc_errors,
                    cobs_errors=self.d.cobs_errors, too_long=self.d.too_long,
                    too_short=self.d.too_short, decode_errors=self.d.decode_errors,
                    garbage_bytes=self.d.garbage_bytes)


cdef list can_frames(const mar_can_frame *f, long n):
    cdef long i
    return [(f[i].id, (<char *>f[i].data)[:f[i].dlc]) for i in range(n)]


def can_encode(raw):
    """[(id, data)] of one message, or a negative status."""
    cdef mar_msg m
    cdef mar_can_frame f[MAR_CAN_FRAMES_MAX]
    to_msg(raw, &m)
    cdef long n = mar_can_encode(&m, f, MAR_CAN_FRAMES_MAX)
    if n < 0:
        return n
    return can_frames(f, n)


def can_encode_setpoints(uint32_t tick, entries):
    """[(id, data)] setpoint PDOs of one tick for any number of entries (saturated to int20)."""
    cdef size_t n = len(entries), i
    cdef size_t room = n if n > 0 else 1
    buf = bytearray(room * (sizeof(mar_setpoint_entry) + sizeof(mar_can_frame)))
    cdef mar_setpoint_entry *es = <mar_setpoint_entry *><uint8_t *>buf
    cdef mar_can_frame *f = <mar_can_frame *>(<uint8_t *>buf + room * sizeof(mar_setpoint_entry))
    try:
        for i in range(n):
            es[i].node, es[i].channel, es[i].counts = entries[i]
    except OverflowError as exc:
        raise ArgumentError(f"setpoint entry {i} out of range: {exc}") from None
    cdef long k = mar_can_encode_setpoints(tick, es, n, f, n)
    if k < 0:
        return k
    return can_frames(f, k)


cdef class CanReceiver:
    """mar_can_rx: unwraps SYNC counters, joins STATUS and CONFIG frames."""
    cdef mar_can_rx rx
    cdef mar_msg m

    def __cinit__(self):
        mar_can_rx_init(&self.rx)

    def feed(self, int can_id, const uint8_t[::1] data):
        """(status, raw): status 1 with a message, 0 for a part, or negative."""
        cdef mar_can_frame f
        cdef Py_ssize_t i, n = data.shape[0]
        if not 0 <= can_id <= 0x7FF or n > 8:
            return (MAR_E_ID, None)
        f.id = <uint16_t>can_id
        f.dlc = <uint8_t>n
        memset(f.data, 0, 8)
        for i in range(n):
            f.data[i] = data[i]
        cdef int r = mar_can_rx_feed(&self.rx, &f, &self.m)
        return (r, from_msg(&self.m) if r == 1 else None)

    @property
    def tick(self):
        """Unwrapped tick of the last SYNC, or None before the first."""
        return self.rx.tick if self.rx.have_tick else None


def fuzz(uint64_t seed, uint64_t frames):
    """mar_fuzz_run without the GIL; the report as a dict."""
    cdef mar_fuzz_report r
    with nogil:
        mar_fuzz_run(seed, frames, &r)
    return r
