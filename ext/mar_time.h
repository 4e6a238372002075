/* Monotonic time in nanoseconds, the one clock the engine uses. */
#ifndef MAR_TIME_H
#define MAR_TIME_H

#include <stdint.h>
#include <time.h>

#define MAR_NS_PER_S INT64_C(1000000000)

/* CLOCK_MONOTONIC now [ns]. */
static inline int64_t mar_now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * MAR_NS_PER_S + ts.tv_nsec;
}

static inline struct timespec mar_timespec(int64_t ns)
{
    struct timespec ts;
    ts.tv_sec = (time_t)(ns / MAR_NS_PER_S);
    ts.tv_nsec = (long)(ns % MAR_NS_PER_S);
    return ts;
}

#endif
