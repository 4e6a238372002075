#include "mar_hist.h"

void mar_hist_reset(mar_hist *h)
{
    for (int i = 0; i < MAR_HIST_BINS; i++)
        atomic_store_explicit(&h->bins[i], 0, memory_order_relaxed);
    atomic_store_explicit(&h->count, 0, memory_order_relaxed);
    atomic_store_explicit(&h->max_ns, 0, memory_order_relaxed);
}

/* Values below 2*SUB ns get a bucket each; above, each power of two is split
 * into SUB equal buckets. */
int mar_hist_index(int64_t v)
{
    if (v < 0)
        v = 0;
    if (v < 2 * MAR_HIST_SUB)
        return (int)v;
    int msb = 63 - __builtin_clzll((unsigned long long)v);
    int shift = msb - 6;                     /* v >> shift lies in [64, 128) */
    int idx = 2 * MAR_HIST_SUB + (shift - 1) * MAR_HIST_SUB + (int)((v >> shift) - MAR_HIST_SUB);
    return idx < MAR_HIST_BINS ? idx : MAR_HIST_BINS - 1;
}

int64_t mar_hist_lower(int i)
{
    if (i < 2 * MAR_HIST_SUB)
        return i;
    int shift = (i - 2 * MAR_HIST_SUB) / MAR_HIST_SUB + 1;
    int sub = (i - 2 * MAR_HIST_SUB) % MAR_HIST_SUB;
    return (int64_t)(MAR_HIST_SUB + sub) << shift;
}

int64_t mar_hist_width(int i)
{
    if (i < 2 * MAR_HIST_SUB)
        return 1;
    return (int64_t)1 << ((i - 2 * MAR_HIST_SUB) / MAR_HIST_SUB + 1);
}

/* Single writer: load + store instead of a read-modify-write. */
static inline void bump(_Atomic uint64_t *c)
{
    atomic_store_explicit(c, atomic_load_explicit(c, memory_order_relaxed) + 1, memory_order_relaxed);
}

void mar_hist_add(mar_hist *h, int64_t v)
{
    bump(&h->bins[mar_hist_index(v)]);
    bump(&h->count);
    if (v > atomic_load_explicit(&h->max_ns, memory_order_relaxed))
        atomic_store_explicit(&h->max_ns, v, memory_order_relaxed);
}

uint64_t mar_hist_count(const mar_hist *h)
{
    return atomic_load_explicit(&h->count, memory_order_relaxed);
}

uint64_t mar_hist_bin(const mar_hist *h, int i)
{
    return atomic_load_explicit(&h->bins[i], memory_order_relaxed);
}

int64_t mar_hist_max(const mar_hist *h)
{
    return atomic_load_explicit(&h->max_ns, memory_order_relaxed);
}

int64_t mar_hist_quantile(const mar_hist *h, double q)
{
    uint64_t total = 0;
    for (int i = 0; i < MAR_HIST_BINS; i++)
        total += atomic_load_explicit(&h->bins[i], memory_order_relaxed);
    if (total == 0)
        return -1;
    if (q < 0.0)
        q = 0.0;
    if (q > 1.0)
        q = 1.0;
    /* rank of the wanted sample, 1-based, rounded up */
    uint64_t rank = (uint64_t)(q * (double)total);
    if ((double)rank < q * (double)total)
        rank++;
    if (rank < 1)
        rank = 1;
    uint64_t seen = 0;
    int64_t max = mar_hist_max(h);
    for (int i = 0; i < MAR_HIST_BINS; i++) {
        seen += atomic_load_explicit(&h->bins[i], memory_order_relaxed);
        if (seen >= rank) {
            int64_t mid = mar_hist_lower(i) + mar_hist_width(i) / 2;
            return mid < max ? mid : max;
        }
    }
    return max;
}
