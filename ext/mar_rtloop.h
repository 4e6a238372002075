/* The real-time loop: a POSIX thread that wakes on an absolute 20 ms grid
 * (clock_nanosleep TIMER_ABSTIME on CLOCK_MONOTONIC) and runs one tick.
 *
 * Overrun policy: when a tick ends after the next deadline, the missed
 * deadlines are counted as overruns and skipped, the loop re-aligns to the
 * next grid point, and the playback clock advances by every elapsed
 * period, so the show keeps real time (like ros2_control's periodic sleep). */
#ifndef MAR_RTLOOP_H
#define MAR_RTLOOP_H

#include <pthread.h>
#include <stdint.h>

#include "mar_engine.h"

typedef struct {
    int priority;        /* SCHED_FIFO priority 1..99; 0 = normal scheduling */
    int cpu;             /* CPU to pin the thread to; -1 = any */
    int lock_memory;     /* 1 = mlockall(MCL_CURRENT | MCL_FUTURE) */
    uint64_t max_ticks;  /* stop by itself after this many ticks; 0 = never */
} mar_rt_options;

/* What the loop was granted; failures to get FIFO, pinning or locked memory
 * are not fatal: the caller warns. */
typedef struct {
    int fifo;            /* 1 if running under SCHED_FIFO */
    int fifo_error;      /* errno of the refusal, 0 if none */
    int pinned;
    int pin_error;
    int memory_locked;
    int lock_error;
} mar_rt_report;

typedef struct {
    mar_engine *engine;
    mar_rt_options opt;
    mar_rt_report report;
    pthread_t thread;
    _Atomic int stop;
    _Atomic int finished;    /* loop left by itself (max_ticks) */
    int started;
} mar_rtloop;

/* Start the loop; 0, or -EBUSY if the engine already runs, or a pthread error. */
int mar_rt_start(mar_rtloop *loop, mar_engine *e, const mar_rt_options *opt);
/* Ask the loop to stop and join it; returns within about one period. */
int mar_rt_stop(mar_rtloop *loop);

#endif
