# Declarations of the protocol codec in firmware_protocol/ (version 1).
# Declarations only: the binding is _protocol.pyx (and the sink in _core.pyx).
from libc.stdint cimport int32_t, uint8_t, uint16_t, uint32_t, uint64_t


cdef extern from "mar_crc.h" nogil:
    uint32_t mar_crc32c(const uint8_t *data, size_t len)


cdef extern from "mar_cobs.h" nogil:
    size_t MAR_COBS_MAX(size_t n)
    size_t mar_cobs_encode(const uint8_t *src, size_t n, uint8_t *out)
    long mar_cobs_decode(const uint8_t *src, size_t n, uint8_t *out, size_t cap)


cdef extern from "mar_proto.h" nogil:
    enum:
        MAR_PROTO_VERSION
        MAR_BROADCAST
        MAR_HEADER_BYTES
        MAR_CRC_BYTES
        MAR_FRAME_MAX
        MAR_PAYLOAD_MAX
        MAR_WIRE_MAX
        MAR_SETPOINT_MAX
        MAR_STATUS_MAX
        MAR_CONFIG_MAX
        MAR_BANDS_MAX
        MAR_BAND_SILENT
        MAR_MSG_SYNC
        MAR_MSG_SETPOINT
        MAR_MSG_ESTOP
        MAR_MSG_ESTOP_RELEASE
        MAR_MSG_CONFIG
        MAR_MSG_STATUS
        MAR_MSG_HEARTBEAT
        MAR_MSG_LOUDNESS
        MAR_MSG_NACK
        MAR_E_SHORT
        MAR_E_CRC
        MAR_E_VERSION
        MAR_E_TYPE
        MAR_E_LENGTH
        MAR_E_VALUE
        MAR_E_COBS
        MAR_E_TOOLONG
        MAR_E_RANGE
        MAR_E_STALE
        MAR_E_INCOMPLETE
        MAR_E_ID

    ctypedef struct mar_setpoint_entry:
        uint8_t node
        uint8_t channel
        int32_t counts

    ctypedef struct mar_channel_config:
        uint8_t channel
        int32_t min_counts
        int32_t max_counts
        uint32_t max_speed
        uint32_t max_accel

    struct mar_msg_sync:
        uint8_t poll
    struct mar_msg_setpoint:
        uint16_t n
        mar_setpoint_entry entry[60]
    struct mar_msg_status:
        uint8_t flags
        uint8_t state
        uint16_t rejected
        uint16_t seq_gaps
        uint8_t n
        int32_t position[59]
    struct mar_msg_heartbeat:
        uint8_t state
    struct mar_msg_config:
        uint32_t tick_period_us
        uint16_t watchdog_ticks
        uint8_t n
        mar_channel_config channel[14]
    struct mar_msg_loudness:
        float value
        uint8_t n_bands
        uint8_t band[16]
    struct mar_msg_nack:
        uint16_t reason
        uint8_t flags
        uint8_t ref_type
        uint32_t ref_seq

    ctypedef struct mar_msg:
        uint8_t type
        uint8_t node
        uint32_t seq
        mar_msg_sync sync
        mar_msg_setpoint setpoint
        mar_msg_status status
        mar_msg_heartbeat heartbeat
        mar_msg_config config
        mar_msg_loudness loudness
        mar_msg_nack nack

    long mar_encode_body(const mar_msg *m, uint8_t *body, size_t cap)
    int mar_decode_body(const uint8_t *body, size_t len, mar_msg *m)
    long mar_encode_frame(const mar_msg *m, uint8_t *wire, size_t cap)
    int mar_decode_frame(const uint8_t *wire, size_t len, mar_msg *m)
    long mar_encode_setpoints(uint32_t tick, const mar_setpoint_entry *entries, size_t n,
                              uint8_t *wire, size_t cap)
    size_t mar_setpoints_wire_max(size_t n)
    int mar_msg_equal(const mar_msg *a, const mar_msg *b)
    int mar_config_reason(const mar_msg *m)
    int mar_reason_of(int status)
    int mar_band_code(float db)
    float mar_band_db(uint8_t code)


cdef extern from "mar_deframer.h" nogil:
    ctypedef struct mar_deframer:
        uint32_t bytes
        uint32_t frames_ok
        uint32_t crc_errors
        uint32_t cobs_errors
        uint32_t too_long
        uint32_t too_short
        uint32_t decode_errors
        uint32_t garbage_bytes
    void mar_deframer_init(mar_deframer *d)
    int mar_deframer_push(mar_deframer *d, uint8_t byte, mar_msg *m)


cdef extern from "mar_proto_can.h" nogil:
    enum:
        MAR_CAN_ESTOP
        MAR_CAN_ESTOP_RELEASE
        MAR_CAN_SYNC
        MAR_CAN_EMCY
        MAR_CAN_STATUS
        MAR_CAN_SETPOINT
        MAR_CAN_POSITION
        MAR_CAN_CONFIG
        MAR_CAN_BANDS
        MAR_CAN_LOUDNESS
        MAR_CAN_HEARTBEAT
        MAR_CAN_NODE_MAX
        MAR_CAN_CHANNELS
        MAR_CAN_COUNTS_MAX
        MAR_CAN_COUNTS_NONE
        MAR_CAN_BANDS_MAX
        MAR_CAN_FRAMES_MAX
    ctypedef struct mar_can_frame:
        uint16_t id
        uint8_t dlc
        uint8_t data[8]
    ctypedef struct mar_can_rx:
        int have_tick
        uint32_t tick
    long mar_can_encode(const mar_msg *m, mar_can_frame *out, size_t cap)
    long mar_can_encode_setpoints(uint32_t tick, const mar_setpoint_entry *entries, size_t n,
                                  mar_can_frame *out, size_t cap)
    void mar_can_rx_init(mar_can_rx *rx)
    int mar_can_rx_feed(mar_can_rx *rx, const mar_can_frame *f, mar_msg *m)


cdef extern from "mar_fuzz.h" nogil:
    ctypedef struct mar_fuzz_report:
        uint64_t frames
        uint64_t clean
        uint64_t clean_lost
        uint64_t mutated
        uint64_t crc_trials
        uint64_t mutated_rejected
        uint64_t mutated_same
        uint64_t accepted_corrupt
        uint64_t crc16_accepted
        uint64_t low_weight
        uint64_t low_weight_accepted
        uint64_t garbage_runs
        uint64_t garbage_bytes
        uint64_t garbage_accepted
        uint64_t wire_bytes
        uint64_t can_frames
        uint64_t can_messages
    void mar_fuzz_run(uint64_t seed, uint64_t n_frames, mar_fuzz_report *r)
