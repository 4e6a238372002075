/* Where each tick's setpoints go: encoded by a codec, then written to a
 * file descriptor from the tick thread, or queued for a Python sender.
 *
 * The codec is a function pointer chosen by mar_sink_set: the version-1
 * protocol (firmware_protocol/SPEC.md) on a serial line or on CAN.
 * Buffers are sized at setup; emitting never allocates.
 *
 * What one tick produces:
 *   serial  one SYNC frame, then the SETPOINT frame(s), COBS-framed, each
 *           ended by 0x00: bytes ready for the line.
 *   CAN     the SYNC frame, then the setpoint PDOs, as MAR_CAN_RECORD_BYTES
 *           records laid out like Linux's struct can_frame (little-endian):
 *             bytes 0..3   identifier, uint32 (11-bit)
 *             byte  4      DLC, 0..8
 *             bytes 5..7   0
 *             bytes 8..15  data; bytes past the DLC are 0
 *           A Python thread hands them to python-can's bus.send(); on a
 *           descriptor (a raw SocketCAN socket) each record is one write().
 *
 * In the ring, a slot is a uint32 length [bytes] followed by that tick's
 * bytes as above. Setpoints go out sorted by (node, channel), so a node's
 * channels form one group (serial) or share PDOs (CAN). */
#ifndef MAR_SINK_H
#define MAR_SINK_H

#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "mar_proto.h"
#include "mar_proto_can.h"
#include "mar_ring.h"

enum mar_sink_kind {
    MAR_SINK_NONE = 0,   /* setpoints are only recorded */
    MAR_SINK_FD = 1,     /* write(2) to a non-blocking descriptor, in the tick */
    MAR_SINK_RING = 2,   /* frames queued in an SPSC ring for a Python thread */
};

enum mar_sink_protocol {
    MAR_SINK_SERIAL = 0, /* COBS frames for a serial line (the default) */
    MAR_SINK_CAN = 1,    /* CAN frames as struct can_frame records */
};

#define MAR_CAN_RECORD_BYTES 16

/* Per-axis addressing and the position -> device counts map. */
typedef struct {
    uint8_t node, channel;
    double scale;        /* [counts/unit] */
    double offset;       /* [counts] at position 0 */
} mar_axis_address;

typedef struct mar_sink mar_sink;

/* Codec: writes one tick (s->entries hold its setpoints); returns bytes or MAR_E_*. */
typedef long (*mar_encode_fn)(mar_sink *s, uint32_t tick, uint8_t *buf, size_t cap);

struct mar_sink {
    int kind;
    int protocol;               /* enum mar_sink_protocol */
    int fd;
    mar_ring ring;              /* slots: uint32 length [bytes] + a tick's bytes */
    mar_encode_fn encode;
    size_t n_axes;
    mar_axis_address *address;  /* n_axes, in the engine's axis order */
    size_t *order;              /* n_axes: axis indexes sorted by (node, channel) */
    mar_setpoint_entry *entries;    /* n_axes, in that order, scratch */
    mar_can_frame *can;         /* 1 + n_axes, scratch */
    uint8_t *frame;             /* frame_cap bytes, scratch */
    size_t frame_cap;           /* [bytes], enough for either protocol */
    uint8_t nodes[256];         /* the nodes addressed, ascending */
    size_t n_nodes;
    int poll_one;               /* serial: each SYNC polls one node in turn, not every node */
    _Atomic uint64_t frames;    /* ticks emitted in full */
    _Atomic uint64_t errors;    /* ticks lost: short write, full ring, codec error */
    _Atomic uint64_t bytes;     /* bytes handed on */
    _Atomic int gone;           /* the errno of a write() that says the receiver is gone for good
                                 * (EIO, ENXIO, ENODEV, EBADF, EPIPE, ...; not a full buffer); latched */
};

/* Largest tick for n axes [bytes], whichever protocol. */
size_t mar_sink_frame_bytes(size_t n_axes);

int mar_sink_init(mar_sink *s, size_t n_axes, const mar_axis_address *address);
/* Serial only (-EINVAL for CAN): one_per_tick 1 makes each tick's SYNC poll
 * one node, in turn (a shared line too slow for every node's STATUS every
 * tick, SPEC.md section 7); 0: every node answers every SYNC. */
int mar_sink_set_poll(mar_sink *s, int one_per_tick);
void mar_sink_free(mar_sink *s);

/* Select the destination and the protocol. ring_slots is used for
 * MAR_SINK_RING. -EINVAL for an address the protocol cannot carry: node
 * 255 (the broadcast address) on serial; on CAN, nodes outside 1..127 or
 * channels above 8. Call before the ticks start. */
int mar_sink_set(mar_sink *s, int kind, int fd, size_t ring_slots, int protocol);

/* Device counts of a position, rounded and saturated to int32. */
int32_t mar_counts(const mar_axis_address *a, double position);

/* 1 when a write() error (an errno) is one no later write() will cure: the
 * device, the pty's other end or the connection is gone (a full buffer,
 * EAGAIN or ENOBUFS, is not). */
int mar_sink_receiver_gone(int err);

/* The receiver is gone (err, an errno, not 0): latched in gone, so the next
 * tick counts every node silent. The tick's own write() sets it; so does a
 * sender outside the tick (the Python thread that hands CAN frames to
 * python-can) when the link's writes fail for good. */
void mar_sink_set_gone(mar_sink *s, int err);

/* Encode and hand on one tick's commands [unit]. Never blocks. */
void mar_sink_emit(mar_sink *s, uint32_t tick, const double *command);

#endif
