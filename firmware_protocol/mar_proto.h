/* Servo protocol version 1: messages, and their serial frames.
 *
 * The byte-by-byte definition, and the reasons, are in SPEC.md. In short,
 * a frame body is
 *
 *   offset  size  field
 *   0       1     version, 1
 *   1       1     message type (MAR_MSG_*; bit 7 set: sent by a node)
 *   2       1     node: addressee (host to node, 0xFF every node) or sender (node to host)
 *   3       4     seq, uint32: the tick for SYNC, SETPOINT and STATUS, else a counter
 *   7       n     payload (its layout depends on the type; its length is the frame's)
 *   7+n     4     CRC-32C of bytes 0 .. 6+n
 *
 * all integers little-endian, and on the wire it is COBS-encoded and ended
 * by one 0x00 byte. There is no length field: the delimiter gives the length.
 *
 * Plain C11, no allocation, no library calls but memcpy/memset: builds for
 * a servo node's microcontroller as it is. */
#ifndef MAR_PROTO_H
#define MAR_PROTO_H

#include <stddef.h>
#include <stdint.h>

#include "mar_cobs.h"

#define MAR_PROTO_VERSION 1
#define MAR_BROADCAST 0xFFu                 /* node address of "every node" */

#define MAR_HEADER_BYTES 7                  /* version, type, node, seq */
#define MAR_CRC_BYTES 4
#define MAR_FRAME_MAX 256                   /* largest body: header + payload + CRC [bytes] */
#define MAR_PAYLOAD_MAX (MAR_FRAME_MAX - MAR_HEADER_BYTES - MAR_CRC_BYTES)   /* 245 bytes */
#define MAR_WIRE_MAX (MAR_COBS_MAX(MAR_FRAME_MAX) + 1)                      /* encoded + 0x00: 259 bytes */

/* Message types. Bit 7 tells the direction, so a node on a shared line
 * skips what other nodes send without decoding it. */
enum mar_msg_type {
    MAR_MSG_SYNC = 0x01,            /* host: a tick begins; STATUS answers it */
    MAR_MSG_SETPOINT = 0x02,        /* host: setpoints of one tick, any nodes (a sync write) */
    MAR_MSG_ESTOP = 0x03,           /* host: latch the e-stop, brake to rest */
    MAR_MSG_ESTOP_RELEASE = 0x04,   /* host: release the latch */
    MAR_MSG_CONFIG = 0x05,          /* host: limits per channel, watchdog, tick period */
    MAR_MSG_STATUS = 0x81,          /* node: actual positions, flags, counters */
    MAR_MSG_HEARTBEAT = 0x82,       /* node: its state, now and then */
    MAR_MSG_LOUDNESS = 0x83,        /* node: loudness of one 20 ms audio frame */
    MAR_MSG_NACK = 0x84,            /* node: a frame was refused (reason 0: CONFIG accepted) */
};
#define MAR_FROM_NODE 0x80u

/* STATUS and NACK flags. Bits 5..7 are reserved and must be 0. */
#define MAR_FLAG_LIMIT     0x01u    /* a setpoint was clamped to the node's limits since the last STATUS */
#define MAR_FLAG_FAULT     0x02u    /* the drive reports a fault */
#define MAR_FLAG_WATCHDOG  0x04u    /* no setpoint within the watchdog time: braking or at rest */
#define MAR_FLAG_FOLLOWING 0x08u    /* following error above the node's threshold */
#define MAR_FLAG_ESTOP     0x10u    /* e-stop latched */
#define MAR_FLAGS_DEFINED  0x1Fu

/* Node states (STATUS, HEARTBEAT): the numbers of CANopen's NMT states. */
enum mar_node_state {
    MAR_STATE_BOOT = 0x00,          /* just started (first HEARTBEAT only) */
    MAR_STATE_STOPPED = 0x04,       /* e-stop latched */
    MAR_STATE_OPERATIONAL = 0x05,   /* following setpoints */
    MAR_STATE_PRE_OPERATIONAL = 0x7F, /* holding: no setpoint yet, or the watchdog tripped */
};

/* NACK reasons (uint16 on the wire; unknown values are passed on as numbers). */
enum mar_reason {
    MAR_REASON_ACCEPTED = 0,        /* not an error: the CONFIG was taken */
    MAR_REASON_BAD_VERSION = 1,
    MAR_REASON_BAD_TYPE = 2,
    MAR_REASON_BAD_LENGTH = 3,
    MAR_REASON_BAD_VALUE = 4,
    MAR_REASON_BAD_CHANNEL = 5,     /* a setpoint or config for a channel the node lacks */
    MAR_REASON_BAD_CONFIG = 6,      /* min > max, speed or acceleration 0, watchdog 0 */
    MAR_REASON_ESTOP_LATCHED = 7,   /* setpoints ignored: e-stop latched (once per latch) */
    MAR_REASON_STALE = 8,           /* CAN: setpoint PDO whose counter is not the last SYNC's */
    MAR_REASON_CONFIG_INCOMPLETE = 9, /* CAN: APPLY without every parameter */
    MAR_REASON_DRIVE_FAULT = 0x1000, /* the drive itself (CANopen's "generic error" range) */
};

/* Status codes of the codec (negative). */
#define MAR_E_SHORT (-1)        /* output buffer too small, or frame shorter than header + CRC */
#define MAR_E_CRC (-2)          /* CRC mismatch */
#define MAR_E_VERSION (-3)      /* not version 1 (the header is still filled in) */
#define MAR_E_TYPE (-4)         /* unknown message type */
#define MAR_E_LENGTH (-5)       /* payload (or CAN DLC) length wrong for the type */
#define MAR_E_VALUE (-6)        /* a field holds a value the protocol does not allow */
#define MAR_E_COBS (-7)         /* invalid COBS encoding */
#define MAR_E_TOOLONG (-8)      /* frame longer than MAR_WIRE_MAX */
#define MAR_E_RANGE (-9)        /* encoder: too many entries, or a value outside the transport's range */
#define MAR_E_STALE (-10)       /* CAN: setpoint PDO without a matching SYNC */
#define MAR_E_INCOMPLETE (-11)  /* CAN: configuration applied before all its parameters came */
#define MAR_E_ID (-12)          /* CAN: identifier outside the mapping */

#define MAR_SETPOINT_MAX 60     /* entries in one SETPOINT frame: (245 - 3) / 4 */
#define MAR_STATUS_MAX 59       /* positions in one STATUS: (245 - 6) / 4 */
#define MAR_CONFIG_MAX 14       /* channels in one CONFIG: (245 - 6) / 17 */

/* LOUDNESS bands (SPEC.md section 4): each band's level is one byte, a code
 * counting 0.5 dB steps down from +6 dB re full scale (code 0) to -121 dB
 * (code 254); code 255 is a band below that, or silent. */
#define MAR_BANDS_MAX 16            /* bands in one serial LOUDNESS */
#define MAR_BAND_TOP_DB 6           /* level of code 0 [dB re full scale] */
#define MAR_BAND_STEPS_PER_DB 2     /* codes per dB: steps of 0.5 dB */
#define MAR_BAND_SILENT 255u        /* below the level of code 254, or 0 */

typedef struct {
    uint8_t node, channel;
    int32_t counts;             /* setpoint [device counts] */
} mar_setpoint_entry;

typedef struct {
    uint8_t channel;
    int32_t min_counts, max_counts;     /* position limits [counts], min <= max */
    uint32_t max_speed;                 /* [counts/s], > 0 */
    uint32_t max_accel;                 /* [counts/s^2], > 0 */
} mar_channel_config;

/* One message, any type. type, node and seq are the header's. */
typedef struct {
    uint8_t type;                       /* enum mar_msg_type */
    uint8_t node;
    uint32_t seq;
    union {
        struct mar_msg_sync {
            uint8_t poll;               /* node that answers with STATUS; 0xFF every node */
        } sync;
        struct mar_msg_setpoint {
            uint16_t n;
            mar_setpoint_entry entry[MAR_SETPOINT_MAX];
        } setpoint;
        struct mar_msg_status {
            uint8_t flags;              /* MAR_FLAG_* */
            uint8_t state;              /* enum mar_node_state */
            uint16_t rejected;          /* frames refused since start, wraps */
            uint16_t seq_gaps;          /* ticks without a setpoint since start, wraps */
            uint8_t n;                  /* channels 0 .. n-1 */
            int32_t position[MAR_STATUS_MAX];   /* actual positions [counts] */
        } status;
        struct mar_msg_heartbeat {
            uint8_t state;              /* enum mar_node_state */
        } heartbeat;
        struct mar_msg_config {
            uint32_t tick_period_us;    /* nominal tick [us], > 0: the watchdog's time base */
            uint16_t watchdog_ticks;    /* [ticks] without a setpoint before braking, > 0 */
            uint8_t n;
            mar_channel_config channel[MAR_CONFIG_MAX];
        } config;
        struct mar_msg_loudness {
            float value;                /* loudness, >= 0 and finite, in the show's loudness unit */
            uint8_t n_bands;            /* 0: the loudness alone (a one-band node) */
            uint8_t band[MAR_BANDS_MAX];   /* band levels, codes (MAR_BAND_*), lowest band first */
        } loudness;
        struct mar_msg_nack {
            uint16_t reason;            /* enum mar_reason */
            uint8_t flags;              /* the node's MAR_FLAG_* now */
            uint8_t ref_type;           /* type of the refused frame */
            uint32_t ref_seq;           /* its seq */
        } nack;
    };
} mar_msg;

/* Body (header, payload, CRC) of m; returns its length [bytes] or MAR_E_*.
 * Refuses what the decoder would refuse, so every encoded body decodes. */
long mar_encode_body(const mar_msg *m, uint8_t *body, size_t cap);

/* Checks the CRC, then reads the body into m: 0 or MAR_E_*. After a good
 * CRC, m->type, node and seq hold the header even when the rest is refused
 * (MAR_E_VERSION, TYPE, LENGTH, VALUE), so a node can answer with a NACK. */
int mar_decode_body(const uint8_t *body, size_t len, mar_msg *m);

/* The serial frame of m: COBS-encoded body and the 0x00 delimiter;
 * returns its length [bytes] (at most MAR_WIRE_MAX) or MAR_E_*. */
long mar_encode_frame(const mar_msg *m, uint8_t *wire, size_t cap);

/* One serial frame (with or without its final 0x00) into m: 0 or MAR_E_*. */
int mar_decode_frame(const uint8_t *wire, size_t len, mar_msg *m);

/* The SETPOINT frames of one tick for any number of entries, packed
 * greedily: consecutive entries of one node with consecutive channels share
 * a group, and a full frame starts the next. Entries sorted by (node,
 * channel) give the fewest bytes. Returns bytes written or MAR_E_*. */
long mar_encode_setpoints(uint32_t tick, const mar_setpoint_entry *entries, size_t n,
                          uint8_t *wire, size_t cap);

/* Room mar_encode_setpoints needs for n entries, whatever their order [bytes]. */
size_t mar_setpoints_wire_max(size_t n);

/* 1 when a and b are the same message (only the fields their type uses). */
int mar_msg_equal(const mar_msg *a, const mar_msg *b);

/* What a node answers a decoded CONFIG with: MAR_REASON_ACCEPTED or
 * MAR_REASON_BAD_CONFIG (min > max, speed, acceleration, watchdog or tick
 * period 0, a channel listed twice). Channels the node lacks are its own check. */
int mar_config_reason(const mar_msg *m);

/* The code of a band level [dB re full scale]: 0 .. 254, rounded to the
 * nearest 0.5 dB step, saturated at code 0 (+6 dB); MAR_BAND_SILENT below
 * -121.25 dB (and for -infinity, the level of silence); MAR_E_VALUE for
 * NaN and +infinity. */
int mar_band_code(float db);

/* The level of a band code [dB re full scale]; -infinity for MAR_BAND_SILENT. */
float mar_band_db(uint8_t code);

/* The NACK reason for a decoder status (MAR_E_VERSION -> BAD_VERSION, ...). */
int mar_reason_of(int status);

#endif
