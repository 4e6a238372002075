#define _GNU_SOURCE
#include "mar_rtloop.h"

#include <errno.h>
#include <sched.h>
#include <string.h>
#include <sys/mman.h>

#include "mar_time.h"

/* Touch the stack once so its pages are present before the first deadline. */
static void prefault_stack(void)
{
    volatile unsigned char buf[64 * 1024];
    for (size_t i = 0; i < sizeof buf; i += 4096)
        buf[i] = 0;
}

static void *loop_main(void *arg)
{
    mar_rtloop *loop = arg;
    mar_engine *e = loop->engine;
    const int64_t period = mar_engine_period_ns(e);
    prefault_stack();

    int64_t deadline = mar_now_ns() + period;   /* first tick one period from now */
    int64_t previous = deadline - period;
    uint64_t ticks = 0;
    while (!atomic_load_explicit(&loop->stop, memory_order_relaxed)) {
        struct timespec ts = mar_timespec(deadline);
        while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR)
            ;
        int64_t woke = mar_now_ns();
        mar_engine_note_wake(e, woke - deadline);

        mar_engine_tick(e, deadline, (deadline - previous) / period);
        int64_t done = mar_now_ns();
        mar_engine_note_compute(e, done - woke);

        previous = deadline;
        deadline += period;
        if (done > deadline) {                  /* missed one or more deadlines */
            int64_t missed = (done - deadline) / period + 1;
            mar_engine_count_overruns(e, (uint64_t)missed);
            deadline += missed * period;        /* back on the grid, in the future */
        }
        if (loop->opt.max_ticks && ++ticks >= loop->opt.max_ticks)
            break;
    }
    atomic_store(&loop->finished, 1);
    return NULL;
}

int mar_rt_start(mar_rtloop *loop, mar_engine *e, const mar_rt_options *opt)
{
    int expected = 0;
    if (!atomic_compare_exchange_strong(mar_engine_running_flag(e), &expected, 1))
        return -EBUSY;
    memset(&loop->report, 0, sizeof loop->report);
    loop->engine = e;
    loop->opt = *opt;
    atomic_init(&loop->stop, 0);
    atomic_init(&loop->finished, 0);

    if (opt->lock_memory) {
        if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0)
            loop->report.memory_locked = 1;
        else
            loop->report.lock_error = errno;
    }

    pthread_attr_t attr;
    pthread_attr_init(&attr);
    if (opt->cpu >= 0) {
        cpu_set_t set;
        CPU_ZERO(&set);
        CPU_SET(opt->cpu, &set);
        int r = pthread_attr_setaffinity_np(&attr, sizeof set, &set);
        loop->report.pinned = r == 0;
        loop->report.pin_error = r;
    }
    int r = EPERM;
    if (opt->priority > 0) {
        struct sched_param sp = { .sched_priority = opt->priority };
        pthread_attr_setinheritsched(&attr, PTHREAD_EXPLICIT_SCHED);
        pthread_attr_setschedpolicy(&attr, SCHED_FIFO);
        pthread_attr_setschedparam(&attr, &sp);
        r = pthread_create(&loop->thread, &attr, loop_main, loop);
        loop->report.fifo = r == 0;
        loop->report.fifo_error = r;
    }
    if (r != 0) {                               /* normal scheduling instead */
        pthread_attr_setinheritsched(&attr, PTHREAD_INHERIT_SCHED);
        r = pthread_create(&loop->thread, &attr, loop_main, loop);
        if (r != 0 && opt->cpu >= 0) {          /* the CPU may not exist */
            pthread_attr_destroy(&attr);
            pthread_attr_init(&attr);
            loop->report.pinned = 0;
            loop->report.pin_error = r;
            r = pthread_create(&loop->thread, &attr, loop_main, loop);
        }
    }
    pthread_attr_destroy(&attr);
    if (r != 0) {
        atomic_store(mar_engine_running_flag(e), 0);
        return -r;
    }
    loop->started = 1;
    return 0;
}

int mar_rt_stop(mar_rtloop *loop)
{
    if (!loop->started)
        return 0;
    atomic_store(&loop->stop, 1);
    int r = pthread_join(loop->thread, NULL);
    loop->started = 0;
    if (loop->report.memory_locked)
        munlockall();
    atomic_store(mar_engine_running_flag(loop->engine), 0);
    return -r;
}
