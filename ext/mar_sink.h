/* Where each tick's setpoints go: encoded by a codec, then written to a
 * file descriptor from the tick thread, or queued for a Python sender.
 *
 * The codec is a function pointer so the protocol can be swapped without
 * touching the tick. Buffers are sized at setup; emitting never allocates. */
#ifndef MAR_SINK_H
#define MAR_SINK_H

#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "mar_ring.h"
#include "mar_setpoint0.h"

enum mar_sink_kind {
    MAR_SINK_NONE = 0,   /* setpoints are only recorded */
    MAR_SINK_FD = 1,     /* write(2) to a non-blocking descriptor, in the tick */
    MAR_SINK_RING = 2,   /* frames queued in an SPSC ring for a Python thread */
};

/* Per-axis addressing and the position -> device counts map. */
typedef struct {
    uint8_t node, channel;
    double scale;        /* [counts/unit] */
    double offset;       /* [counts] at position 0 */
} mar_axis_address;

/* Codec: writes the frames for one tick; returns bytes or a negative error. */
typedef long (*mar_encode_fn)(uint32_t tick, const mar_sp0_entry *entries, size_t n,
                              uint8_t *buf, size_t cap);

typedef struct {
    int kind;
    int fd;
    mar_ring ring;              /* slots: uint32 length [bytes] + frame */
    mar_encode_fn encode;
    size_t n_axes;
    mar_axis_address *address;  /* n_axes */
    mar_sp0_entry *entries;     /* n_axes, scratch */
    uint8_t *frame;             /* frame_cap bytes, scratch */
    size_t frame_cap;           /* [bytes] */
    _Atomic uint64_t frames;    /* ticks emitted in full */
    _Atomic uint64_t errors;    /* ticks lost: short write, full ring, codec error */
    _Atomic uint64_t bytes;     /* bytes handed on */
} mar_sink;

/* Largest encoded tick [bytes] for n axes with the version-0 codec. */
size_t mar_sink_frame_bytes(size_t n_axes);

int mar_sink_init(mar_sink *s, size_t n_axes, const mar_axis_address *address);
void mar_sink_free(mar_sink *s);
/* Select the destination. ring_slots is used for MAR_SINK_RING. */
int mar_sink_set(mar_sink *s, int kind, int fd, size_t ring_slots);

/* Device counts of a position, rounded and saturated to int32. */
int32_t mar_counts(const mar_axis_address *a, double position);

/* Encode and hand on one tick's commands [unit]. Never blocks. */
void mar_sink_emit(mar_sink *s, uint32_t tick, const double *command);

#endif
