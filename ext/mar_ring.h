/* Single-producer single-consumer ring of fixed-size slots.
 *
 * The producer never blocks: when the ring is full the item is dropped and
 * counted. Memory is allocated once by mar_ring_init, never in push/pop. */
#ifndef MAR_RING_H
#define MAR_RING_H

#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

typedef struct {
    uint8_t *slots;
    size_t slot_size;                       /* [bytes] */
    size_t capacity;                        /* slots, a power of two */
    _Alignas(64) _Atomic size_t head;       /* next slot to write (producer) */
    _Alignas(64) _Atomic size_t tail;       /* next slot to read (consumer) */
    _Alignas(64) _Atomic uint64_t dropped;  /* items refused because full */
} mar_ring;

/* capacity is rounded up to a power of two. Returns 0 or -ENOMEM/-EINVAL. */
int mar_ring_init(mar_ring *r, size_t slot_size, size_t capacity);
void mar_ring_free(mar_ring *r);

/* Producer: a slot to fill, or NULL (and one more drop) when full. */
void *mar_ring_claim(mar_ring *r);
void mar_ring_publish(mar_ring *r);
/* Producer convenience: copy size <= slot_size bytes in; 0 or -ENOBUFS. */
int mar_ring_push(mar_ring *r, const void *item, size_t size);

/* Consumer: copy up to max_items whole slots into dst; returns the count. */
size_t mar_ring_pop(mar_ring *r, void *dst, size_t max_items);
uint64_t mar_ring_dropped(const mar_ring *r);

#endif
