/* What the standalone C tests share: an allocation counter (link with
 * -Wl,--wrap=malloc,--wrap=calloc,--wrap=realloc,--wrap=free), a CHECK that
 * counts failures and goes on, and a fixed-seed generator. Included by one
 * test file per program. */
#ifndef MAR_TEST_H
#define MAR_TEST_H

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

static long allocations;    /* heap calls so far */
void *__real_malloc(size_t n);
void *__real_calloc(size_t n, size_t m);
void *__real_realloc(void *p, size_t n);
void __real_free(void *p);
void *__wrap_malloc(size_t n) { allocations++; return __real_malloc(n); }
void *__wrap_calloc(size_t n, size_t m) { allocations++; return __real_calloc(n, m); }
void *__wrap_realloc(void *p, size_t n) { allocations++; return __real_realloc(p, n); }
void __wrap_free(void *p) { if (p) allocations++; __real_free(p); }

static int failures;
#define CHECK(cond, ...)                                               \
    do {                                                               \
        if (!(cond)) {                                                 \
            failures++;                                                \
            fprintf(stderr, "FAIL %s:%d: ", __FILE__, __LINE__);       \
            fprintf(stderr, __VA_ARGS__);                              \
            fputc('\n', stderr);                                       \
        }                                                              \
    } while (0)

/* xorshift64*: the same numbers on every machine */
static uint64_t rng_state = 20261122u;
static inline double uniform(double lo, double hi)
{
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    uint64_t x = rng_state * UINT64_C(2685821657736338717);
    return lo + (hi - lo) * (double)(x >> 11) / 9007199254740992.0;
}

#endif
