#include "mar_sink.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* The tick's SYNC: every node answers (poll 0xFF), or the one in turn. */
static mar_msg sync_message(const mar_sink *s, uint32_t tick)
{
    mar_msg sync;
    memset(&sync, 0, sizeof sync);
    sync.type = MAR_MSG_SYNC;
    sync.node = MAR_BROADCAST;
    sync.seq = tick;
    sync.sync.poll = s->poll_one && s->n_nodes ? s->nodes[tick % s->n_nodes] : MAR_BROADCAST;
    return sync;
}

/* Serial: SYNC, then the setpoints in as few SETPOINT frames as fit. */
static long encode_serial(mar_sink *s, uint32_t tick, uint8_t *buf, size_t cap)
{
    mar_msg sync = sync_message(s, tick);
    long a = mar_encode_frame(&sync, buf, cap);
    if (a < 0)
        return a;
    long b = mar_encode_setpoints(tick, s->entries, s->n_axes, buf + a, cap - (size_t)a);
    return b < 0 ? b : a + b;
}

/* CAN: SYNC, then the setpoint PDOs, as struct can_frame records. */
static long encode_can(mar_sink *s, uint32_t tick, uint8_t *buf, size_t cap)
{
    mar_msg sync = sync_message(s, tick);
    long a = mar_can_encode(&sync, s->can, 1);
    if (a < 0)
        return a;
    long b = mar_can_encode_setpoints(tick, s->entries, s->n_axes, s->can + 1, s->n_axes);
    if (b < 0)
        return b;
    size_t n = (size_t)(a + b);
    if (cap < n * MAR_CAN_RECORD_BYTES)
        return MAR_E_SHORT;
    memset(buf, 0, n * MAR_CAN_RECORD_BYTES);
    for (size_t i = 0; i < n; i++) {
        uint8_t *r = buf + i * MAR_CAN_RECORD_BYTES;
        r[0] = (uint8_t)s->can[i].id;
        r[1] = (uint8_t)(s->can[i].id >> 8);
        r[4] = s->can[i].dlc;
        memcpy(r + 8, s->can[i].data, s->can[i].dlc);
    }
    return (long)(n * MAR_CAN_RECORD_BYTES);
}

size_t mar_sink_frame_bytes(size_t n_axes)
{
    size_t serial = MAR_WIRE_MAX + mar_setpoints_wire_max(n_axes);
    size_t can = (1 + mar_can_setpoints_max(n_axes)) * MAR_CAN_RECORD_BYTES;
    return serial > can ? serial : can;
}

static int by_address(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return (x > y) - (x < y);
}

int mar_sink_init(mar_sink *s, size_t n_axes, const mar_axis_address *address)
{
    memset(s, 0, sizeof *s);
    s->kind = MAR_SINK_NONE;
    s->protocol = MAR_SINK_SERIAL;
    s->fd = -1;
    s->encode = encode_serial;
    s->n_axes = n_axes;
    s->frame_cap = mar_sink_frame_bytes(n_axes);
    s->address = malloc(n_axes * sizeof *s->address);
    s->order = malloc(n_axes * sizeof *s->order);
    s->entries = malloc(n_axes * sizeof *s->entries);
    s->can = malloc((1 + n_axes) * sizeof *s->can);
    s->frame = malloc(s->frame_cap);
    uint64_t *keys = malloc(n_axes * sizeof *keys);
    if (!s->address || !s->order || !s->entries || !s->can || !s->frame || (n_axes && !keys)) {
        free(keys);
        mar_sink_free(s);
        return -ENOMEM;
    }
    memcpy(s->address, address, n_axes * sizeof *address);
    /* sorted by (node, channel), ties in axis order: key = node, channel, index */
    for (size_t i = 0; i < n_axes; i++)
        keys[i] = (uint64_t)address[i].node << 56 | (uint64_t)address[i].channel << 48 | (uint64_t)i;
    if (n_axes)
        qsort(keys, n_axes, sizeof *keys, by_address);
    for (size_t k = 0; k < n_axes; k++) {
        size_t i = (size_t)(keys[k] & ((UINT64_C(1) << 48) - 1));
        s->order[k] = i;
        s->entries[k].node = address[i].node;
        s->entries[k].channel = address[i].channel;
        s->entries[k].counts = 0;
        if (s->n_nodes == 0 || s->nodes[s->n_nodes - 1] != address[i].node)
            s->nodes[s->n_nodes++] = address[i].node;
    }
    free(keys);
    return 0;
}

int mar_sink_set_poll(mar_sink *s, int one_per_tick)
{
    if (one_per_tick && s->protocol != MAR_SINK_SERIAL)
        return -EINVAL;                 /* a CAN SYNC always polls every node */
    s->poll_one = one_per_tick != 0;
    return 0;
}

void mar_sink_free(mar_sink *s)
{
    if (s->ring.slots)
        mar_ring_free(&s->ring);
    free(s->address);
    free(s->order);
    free(s->entries);
    free(s->can);
    free(s->frame);
    s->address = NULL;
    s->order = NULL;
    s->entries = NULL;
    s->can = NULL;
    s->frame = NULL;
}

int mar_sink_set(mar_sink *s, int kind, int fd, size_t ring_slots, int protocol)
{
    if (kind == MAR_SINK_FD && fd < 0)
        return -EBADF;
    if (kind != MAR_SINK_NONE && kind != MAR_SINK_FD && kind != MAR_SINK_RING)
        return -EINVAL;
    if (protocol != MAR_SINK_SERIAL && protocol != MAR_SINK_CAN)
        return -EINVAL;
    for (size_t i = 0; i < s->n_axes; i++) {
        const mar_axis_address *a = &s->address[i];
        if (protocol == MAR_SINK_SERIAL ? a->node == MAR_BROADCAST
            : a->node < 1 || a->node > MAR_CAN_NODE_MAX || a->channel >= MAR_CAN_CHANNELS)
            return -EINVAL;
    }
    if (kind == MAR_SINK_RING && !s->ring.slots) {
        int r = mar_ring_init(&s->ring, sizeof(uint32_t) + s->frame_cap, ring_slots);
        if (r < 0)
            return r;
    }
    s->protocol = protocol;
    s->encode = protocol == MAR_SINK_CAN ? encode_can : encode_serial;
    if (protocol == MAR_SINK_CAN)
        s->poll_one = 0;
    s->fd = fd;
    s->kind = kind;
    return 0;
}

int32_t mar_counts(const mar_axis_address *a, double position)
{
    double c = nearbyint(a->offset + a->scale * position);
    if (!(c > (double)INT32_MIN))        /* NaN lands here too */
        return c != c ? 0 : INT32_MIN;
    if (c > (double)INT32_MAX)
        return INT32_MAX;
    return (int32_t)c;
}

int mar_sink_receiver_gone(int err)
{
    return err == EIO || err == ENXIO || err == ENODEV || err == EBADF || err == EPIPE
        || err == ECONNRESET || err == ENOTCONN || err == ENETDOWN;
}

/* The tick's bytes to the descriptor: one write for serial, one per record
 * for CAN (a SocketCAN socket takes one frame per write). 1 if all went. */
static int write_out(mar_sink *s, size_t len)
{
    size_t step = s->protocol == MAR_SINK_CAN ? MAR_CAN_RECORD_BYTES : len;
    int all = 1;
    for (size_t at = 0; at < len; at += step) {
        ssize_t w = write(s->fd, s->frame + at, step);
        if (w > 0)
            atomic_fetch_add_explicit(&s->bytes, (uint64_t)w, memory_order_relaxed);
        if (w != (ssize_t)step) {
            all = 0;
            if (w < 0 && errno != EAGAIN) { /* the receiver is gone: no use trying the rest */
                if (mar_sink_receiver_gone(errno))
                    mar_sink_set_gone(s, errno);
                break;
            }
        }
    }
    return all;
}

void mar_sink_set_gone(mar_sink *s, int err)
{
    int none = 0;
    atomic_compare_exchange_strong_explicit(&s->gone, &none, err, memory_order_relaxed, memory_order_relaxed);
}

void mar_sink_emit(mar_sink *s, uint32_t tick, const double *command)
{
    if (s->kind == MAR_SINK_NONE)
        return;
    for (size_t k = 0; k < s->n_axes; k++) {
        size_t i = s->order[k];
        s->entries[k].counts = mar_counts(&s->address[i], command[i]);
    }
    int ok = 0;
    if (s->kind == MAR_SINK_FD) {
        long len = s->encode(s, tick, s->frame, s->frame_cap);
        if (len > 0)
            ok = write_out(s, (size_t)len);
    } else {
        uint8_t *slot = mar_ring_claim(&s->ring);
        if (slot) {
            long len = s->encode(s, tick, slot + sizeof(uint32_t), s->frame_cap);
            if (len > 0) {
                uint32_t n = (uint32_t)len;
                memcpy(slot, &n, sizeof n);
                mar_ring_publish(&s->ring);
                atomic_fetch_add_explicit(&s->bytes, n, memory_order_relaxed);
                ok = 1;
            }
        }
    }
    atomic_fetch_add_explicit(ok ? &s->frames : &s->errors, 1, memory_order_relaxed);
}
