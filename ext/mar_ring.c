#include "mar_ring.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>

int mar_ring_init(mar_ring *r, size_t slot_size, size_t capacity)
{
    if (slot_size == 0 || capacity == 0 || capacity > ((size_t)1 << 30))
        return -EINVAL;
    size_t cap = 1;
    while (cap < capacity)
        cap <<= 1;
    r->slots = calloc(cap, slot_size);
    if (r->slots == NULL)
        return -ENOMEM;
    r->slot_size = slot_size;
    r->capacity = cap;
    atomic_init(&r->head, 0);
    atomic_init(&r->tail, 0);
    atomic_init(&r->dropped, 0);
    return 0;
}

void mar_ring_free(mar_ring *r)
{
    free(r->slots);
    r->slots = NULL;
    r->capacity = 0;
}

void *mar_ring_claim(mar_ring *r)
{
    size_t head = atomic_load_explicit(&r->head, memory_order_relaxed);
    size_t tail = atomic_load_explicit(&r->tail, memory_order_acquire);
    if (head - tail >= r->capacity) {
        atomic_fetch_add_explicit(&r->dropped, 1, memory_order_relaxed);
        return NULL;
    }
    return r->slots + (head & (r->capacity - 1)) * r->slot_size;
}

void mar_ring_publish(mar_ring *r)
{
    size_t head = atomic_load_explicit(&r->head, memory_order_relaxed);
    atomic_store_explicit(&r->head, head + 1, memory_order_release);
}

int mar_ring_push(mar_ring *r, const void *item, size_t size)
{
    if (size > r->slot_size)
        return -EINVAL;
    void *slot = mar_ring_claim(r);
    if (slot == NULL)
        return -ENOBUFS;
    memcpy(slot, item, size);
    mar_ring_publish(r);
    return 0;
}

size_t mar_ring_pop(mar_ring *r, void *dst, size_t max_items)
{
    size_t tail = atomic_load_explicit(&r->tail, memory_order_relaxed);
    size_t head = atomic_load_explicit(&r->head, memory_order_acquire);
    size_t n = head - tail;
    if (n > max_items)
        n = max_items;
    uint8_t *out = dst;
    for (size_t i = 0; i < n; i++) {
        const uint8_t *slot = r->slots + ((tail + i) & (r->capacity - 1)) * r->slot_size;
        memcpy(out + i * r->slot_size, slot, r->slot_size);
    }
    atomic_store_explicit(&r->tail, tail + n, memory_order_release);
    return n;
}

uint64_t mar_ring_dropped(const mar_ring *r)
{
    return atomic_load_explicit(&r->dropped, memory_order_relaxed);
}
