#include "mar_sink.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* The version-0 codec carries at most 255 entries per record, so a tick is
 * as many records as that takes, back to back. */
static long encode_sp0(uint32_t tick, const mar_sp0_entry *entries, size_t n,
                       uint8_t *buf, size_t cap)
{
    size_t used = 0;
    for (size_t first = 0; first < n; first += MAR_SP0_MAX_ENTRIES) {
        size_t count = n - first < MAR_SP0_MAX_ENTRIES ? n - first : MAR_SP0_MAX_ENTRIES;
        long r = mar_sp0_encode(tick, entries + first, count, buf + used, cap - used);
        if (r < 0)
            return r;
        used += (size_t)r;
    }
    return (long)used;
}

size_t mar_sink_frame_bytes(size_t n_axes)
{
    size_t records = (n_axes + MAR_SP0_MAX_ENTRIES - 1) / MAR_SP0_MAX_ENTRIES;
    return records * mar_sp0_size(0) + n_axes * MAR_SP0_ENTRY;
}

int mar_sink_init(mar_sink *s, size_t n_axes, const mar_axis_address *address)
{
    memset(s, 0, sizeof *s);
    s->kind = MAR_SINK_NONE;
    s->fd = -1;
    s->encode = encode_sp0;
    s->n_axes = n_axes;
    s->frame_cap = mar_sink_frame_bytes(n_axes);
    s->address = malloc(n_axes * sizeof *s->address);
    s->entries = malloc(n_axes * sizeof *s->entries);
    s->frame = malloc(s->frame_cap);
    if (!s->address || !s->entries || !s->frame) {
        mar_sink_free(s);
        return -ENOMEM;
    }
    memcpy(s->address, address, n_axes * sizeof *address);
    for (size_t i = 0; i < n_axes; i++) {
        s->entries[i].node = address[i].node;
        s->entries[i].channel = address[i].channel;
    }
    return 0;
}

void mar_sink_free(mar_sink *s)
{
    if (s->ring.slots)
        mar_ring_free(&s->ring);
    free(s->address);
    free(s->entries);
    free(s->frame);
    s->address = NULL;
    s->entries = NULL;
    s->frame = NULL;
}

int mar_sink_set(mar_sink *s, int kind, int fd, size_t ring_slots)
{
    if (kind == MAR_SINK_FD && fd < 0)
        return -EBADF;
    if (kind != MAR_SINK_NONE && kind != MAR_SINK_FD && kind != MAR_SINK_RING)
        return -EINVAL;
    if (kind == MAR_SINK_RING && !s->ring.slots) {
        int r = mar_ring_init(&s->ring, sizeof(uint32_t) + s->frame_cap, ring_slots);
        if (r < 0)
            return r;
    }
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

void mar_sink_emit(mar_sink *s, uint32_t tick, const double *command)
{
    if (s->kind == MAR_SINK_NONE)
        return;
    for (size_t i = 0; i < s->n_axes; i++)
        s->entries[i].counts = mar_counts(&s->address[i], command[i]);

    int ok = 0;
    if (s->kind == MAR_SINK_FD) {
        long len = s->encode(tick, s->entries, s->n_axes, s->frame, s->frame_cap);
        if (len > 0) {
            ssize_t w = write(s->fd, s->frame, (size_t)len);
            ok = w == len;
            if (w > 0)
                atomic_fetch_add_explicit(&s->bytes, (uint64_t)w, memory_order_relaxed);
        }
    } else {
        uint8_t *slot = mar_ring_claim(&s->ring);
        if (slot) {
            long len = s->encode(tick, s->entries, s->n_axes, slot + sizeof(uint32_t), s->frame_cap);
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
