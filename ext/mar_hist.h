/* Log-linear histogram of durations [ns], about 1.6 % relative resolution.
 *
 * Written by one thread (the tick), read by any: counters are relaxed
 * atomics so a reader never sees a torn value. Fixed size, no allocation. */
#ifndef MAR_HIST_H
#define MAR_HIST_H

#include <stdatomic.h>
#include <stdint.h>

#define MAR_HIST_SUB 64                      /* sub-buckets per power of two */
#define MAR_HIST_BINS (2 * MAR_HIST_SUB + 40 * MAR_HIST_SUB)

typedef struct {
    _Atomic uint64_t bins[MAR_HIST_BINS];
    _Atomic uint64_t count;
    _Atomic int64_t max_ns;                  /* largest value seen [ns] */
} mar_hist;

void mar_hist_reset(mar_hist *h);
void mar_hist_add(mar_hist *h, int64_t value_ns);
/* Value [ns] at quantile q in [0, 1] (midpoint of its bucket, capped at the
 * exact maximum); -1 when empty. */
int64_t mar_hist_quantile(const mar_hist *h, double q);
uint64_t mar_hist_count(const mar_hist *h);
uint64_t mar_hist_bin(const mar_hist *h, int index);         /* samples in one bucket */
int64_t mar_hist_max(const mar_hist *h);

/* Bucket index of a value, and a bucket's lower bound and width [ns]. */
int mar_hist_index(int64_t value_ns);
int64_t mar_hist_lower(int index);
int64_t mar_hist_width(int index);

#endif
