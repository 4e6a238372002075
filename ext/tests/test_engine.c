/* Standalone C test of the engine, the rings, the histogram and the
 * version-0 codec. Built by tests/test_c_build.py with -Wall -Wextra -Werror
 * under AddressSanitizer and UBSan, and linked with --wrap=malloc (and
 * calloc, realloc, free) to prove that no tick allocates. */
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mar_engine.h"
#include "mar_hist.h"
#include "mar_ring.h"
#include "mar_rtloop.h"
#include "mar_setpoint0.h"

/* --- allocation counter (link with -Wl,--wrap=malloc,...) --- */
static long allocations;
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

/* xorshift64*: a fixed-seed generator, same numbers on every machine */
static uint64_t rng_state = 20261122u;
static double uniform(double lo, double hi)
{
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    uint64_t x = rng_state * UINT64_C(2685821657736338717);
    return lo + (hi - lo) * (double)(x >> 11) / 9007199254740992.0;
}

/* Random figure and show; every tick's commands checked against the limits. */
static void test_limits_random(int cases)
{
    enum { AXES = 6, TICKS = 400 };
    for (int c = 0; c < cases; c++) {
        mar_axis axes[AXES];
        double show[AXES * TICKS], loud[TICKS];
        for (int j = 0; j < AXES; j++) {
            double lo = uniform(-2, 0), hi = lo + uniform(0.1, 3);
            axes[j] = (mar_axis){
                .limits = { lo, hi, uniform(0.05, 3), uniform(0.1, 20) },
                .dead_time = uniform(0, 0.2), .time_constant = uniform(0, 0.3),
                .start = uniform(lo, hi),
                .address = { (uint8_t)j, 0, 1000.0, 0.0 },
            };
            /* wild show: jumps, overshoot beyond the limits, noise */
            for (int k = 0; k < TICKS; k++)
                show[j * TICKS + k] = uniform(lo - 0.5, hi + 0.5) * (k % 37 < 20 ? 1.0 : 0.3);
        }
        for (int k = 0; k < TICKS; k++)
            loud[k] = uniform(0, 1);
        mar_engine_options opt = { 0.02, c % 3, c % 2, TICKS, 16, c % 5 == 0 };
        int status;
        mar_engine *e = mar_engine_create(&opt, axes, AXES, show, TICKS, loud, &status);
        CHECK(e != NULL, "create failed: %d", status);
        if (!e)
            continue;
        mar_engine_set_rate(e, uniform(0, 3));
        size_t rs = mar_engine_record_size(e);
        unsigned char *rec = malloc(rs * TICKS);
        double pose[AXES];
        for (int j = 0; j < AXES; j++)   /* some targets outside the limits: clamped */
            pose[j] = uniform(axes[j].limits.pos_min - 0.2, axes[j].limits.pos_max + 0.2);
        long before = allocations;
        mar_engine_step(e, TICKS / 4);
        mar_engine_seek(e, uniform(0, TICKS));
        mar_engine_set_rate(e, uniform(0, 3));
        mar_engine_step(e, TICKS / 4);
        /* online moves in the middle of it all: go to, stop, blend back in */
        uint64_t k1 = (uint64_t)uniform(1, TICKS / 8), k2 = (uint64_t)uniform(1, TICKS / 8);
        mar_engine_request(e, MAR_REQ_GOTO, pose, c % 2);
        mar_engine_step(e, k1);
        mar_engine_request(e, c % 3 ? MAR_REQ_STOP : MAR_REQ_GOTO, pose, 0);
        mar_engine_step(e, k2);
        mar_engine_request(e, MAR_REQ_BLEND, NULL, 1);
        mar_engine_step(e, TICKS - 2 * (TICKS / 4) - k1 - k2);
        CHECK(allocations == before, "ticks allocated %ld times", allocations - before);
        size_t n = mar_engine_drain_records(e, rec, TICKS);
        CHECK(n == TICKS, "recorded %zu of %d ticks", n, TICKS);
        double prev_x[AXES], prev_v[AXES];
        for (int j = 0; j < AXES; j++) {
            prev_x[j] = axes[j].start;
            prev_v[j] = 0.0;
        }
        for (size_t k = 0; k < n; k++) {
            const double *cmd = (const double *)(rec + k * rs + sizeof(mar_record));
            for (int j = 0; j < AXES; j++) {
                const mar_limits *l = &axes[j].limits;
                double v = (cmd[j] - prev_x[j]) / 0.02;
                double tol = 1e-9 * (1.0 + fabs(l->pos_max) + fabs(l->pos_min));
                CHECK(cmd[j] >= l->pos_min - tol && cmd[j] <= l->pos_max + tol,
                      "case %d tick %zu axis %d: position %g outside [%g, %g]", c, k, j, cmd[j], l->pos_min, l->pos_max);
                CHECK(fabs(v) <= l->max_speed * (1 + 1e-9) + 1e-9,
                      "case %d tick %zu axis %d: speed %g > %g", c, k, j, v, l->max_speed);
                CHECK(fabs(v - prev_v[j]) <= l->max_accel * 0.02 * (1 + 1e-9) + 1e-9,
                      "case %d tick %zu axis %d: acceleration %g > %g", c, k, j, (v - prev_v[j]) / 0.02, l->max_accel);
                prev_x[j] = cmd[j];
                prev_v[j] = v;
            }
        }
        free(rec);
        mar_engine_destroy(e);
    }
}

static void test_bad_inputs(void)
{
    mar_axis axis = { .limits = { -1, 1, 1, 5 }, .start = 0, .address = { 1, 0, 100, 0 } };
    double show[4] = { 0, 0.1, 0.2, 0.3 }, loud[4] = { 0, 0, 0, 0 };
    mar_engine_options opt = { 0.02, MAR_LEAD_DEAD_TIME_LAG, MAR_INTERP_CUBIC, 8, 4, 0 };
    int status;
    mar_engine *e = mar_engine_create(&opt, &axis, 1, show, 4, loud, &status);
    CHECK(e != NULL, "create");
    CHECK(mar_engine_set_rate(e, NAN) < 0, "NaN rate accepted");
    CHECK(mar_engine_seek(e, INFINITY) < 0, "infinite seek accepted");
    CHECK(mar_engine_push_loudness(e, -1.0) < 0, "negative loudness accepted");
    CHECK(mar_engine_push_loudness(e, NAN) < 0, "NaN loudness accepted");
    CHECK(mar_engine_push_loudness(e, 0.5) == 0, "good loudness refused");
    mar_engine_step(e, 3);
    mar_record r;
    double cmd;
    CHECK(mar_engine_snapshot(e, &r, &cmd) == 0, "snapshot");
    CHECK(r.live_loudness == 0.5, "live loudness %g", r.live_loudness);
    mar_counters cnt;
    mar_engine_counters(e, &cnt);
    CHECK(cnt.bad_input == 4, "bad inputs counted %llu", (unsigned long long)cnt.bad_input);
    mar_engine_destroy(e);

    /* refused configurations */
    double nan_show[4] = { 0, NAN, 0, 0 };
    CHECK(mar_engine_create(&opt, &axis, 1, nan_show, 4, loud, &status) == NULL, "NaN show accepted");
    mar_axis reversed = axis;
    reversed.limits.pos_min = 2;
    CHECK(mar_engine_create(&opt, &reversed, 1, show, 4, loud, &status) == NULL, "reversed limits accepted");
    mar_axis outside = axis;
    outside.start = 5;
    CHECK(mar_engine_create(&opt, &outside, 1, show, 4, loud, &status) == NULL, "start outside limits accepted");
}

static void test_codec(void)
{
    mar_sp0_entry in[255], out[255];
    uint8_t buf[2048];
    for (int round = 0; round < 500; round++) {
        size_t n = 1 + (size_t)uniform(0, 255);
        for (size_t i = 0; i < n; i++)
            in[i] = (mar_sp0_entry){ (uint8_t)uniform(0, 256), (uint8_t)uniform(0, 256),
                                     (int32_t)uniform(-2147483648.0, 2147483647.0) };
        uint32_t tick = (uint32_t)uniform(0, 4294967295.0), got_tick;
        long len = mar_sp0_encode(tick, in, n, buf, sizeof buf);
        CHECK(len == (long)mar_sp0_size(n), "encoded %ld bytes", len);
        size_t got_n;
        CHECK(mar_sp0_decode(buf, (size_t)len, &got_tick, out, 255, &got_n) == len, "decode");
        int same = got_tick == tick && got_n == n;
        for (size_t i = 0; same && i < n; i++)   /* field by field: the struct has padding */
            same = in[i].node == out[i].node && in[i].channel == out[i].channel && in[i].counts == out[i].counts;
        CHECK(same, "round trip of %zu entries", n);
        /* any single flipped bit is caught, and a short buffer never overruns */
        size_t at = (size_t)uniform(0, (double)len);
        buf[at] ^= (uint8_t)(1u << (int)uniform(0, 8));
        CHECK(mar_sp0_decode(buf, (size_t)len, &got_tick, out, 255, &got_n) < 0, "flipped bit accepted");
        CHECK(mar_sp0_decode(buf, (size_t)len - 1, &got_tick, out, 255, &got_n) < 0, "short record accepted");
    }
}

static void test_ring_and_hist(void)
{
    mar_ring r;
    CHECK(mar_ring_init(&r, sizeof(int), 5) == 0, "ring init");
    CHECK(r.capacity == 8, "capacity rounded to %zu", r.capacity);
    for (int i = 0; i < 10; i++)
        mar_ring_push(&r, &i, sizeof i);
    CHECK(mar_ring_dropped(&r) == 2, "dropped %llu", (unsigned long long)mar_ring_dropped(&r));
    int out[10];
    CHECK(mar_ring_pop(&r, out, 10) == 8 && out[0] == 0 && out[7] == 7, "pop order");
    mar_ring_free(&r);

    static mar_hist h;
    mar_hist_reset(&h);
    for (int64_t v = 1; v <= 100000; v++)
        mar_hist_add(&h, v);
    int64_t p50 = mar_hist_quantile(&h, 0.5), p99 = mar_hist_quantile(&h, 0.99);
    CHECK(fabs((double)p50 - 50000) < 0.02 * 50000, "p50 %lld", (long long)p50);
    CHECK(fabs((double)p99 - 99000) < 0.02 * 99000, "p99 %lld", (long long)p99);
    CHECK(mar_hist_max(&h) == 100000, "max");
    for (int i = 0; i < MAR_HIST_BINS; i++) {
        int64_t lo = mar_hist_lower(i);
        CHECK(mar_hist_index(lo) == i && mar_hist_index(lo + mar_hist_width(i) - 1) == i,
              "bucket %d bounds", i);
        if (failures)
            break;
    }
}

static void test_rtloop(void)
{
    mar_axis axis = { .limits = { -1, 1, 1, 5 }, .start = 0, .address = { 1, 0, 100, 0 } };
    double show[100] = { 0 }, loud[100] = { 0 };
    mar_engine_options opt = { 0.005, MAR_LEAD_DEAD_TIME_LAG, MAR_INTERP_CUBIC, 256, 4, 0 };
    int status;
    mar_engine *e = mar_engine_create(&opt, &axis, 1, show, 100, loud, &status);
    mar_rtloop loop;
    memset(&loop, 0, sizeof loop);
    mar_rt_options ro = { 0, -1, 0, 40 };
    long before = allocations;
    CHECK(mar_rt_start(&loop, e, &ro) == 0, "rt start");
    CHECK(mar_rt_start(&loop, e, &ro) == -16 /* EBUSY */, "second start accepted");
    CHECK(mar_engine_step(e, 1) < 0, "step while running");
    while (!atomic_load(&loop.finished))
        ;
    mar_rt_stop(&loop);
    (void)before;  /* thread creation allocates its stack: not a tick */
    mar_counters c;
    mar_engine_counters(e, &c);
    CHECK(c.ticks == 40, "rt ticks %llu", (unsigned long long)c.ticks);
    CHECK(mar_hist_count(mar_engine_wake_hist(e)) == 40, "wake samples");
    mar_engine_destroy(e);
}

int main(void)
{
    signal(SIGPIPE, SIG_IGN);
    test_limits_random(300);
    test_bad_inputs();
    test_codec();
    test_ring_and_hist();
    test_rtloop();
    if (failures) {
        fprintf(stderr, "%d checks failed\n", failures);
        return 1;
    }
    printf("C engine tests passed\n");
    return 0;
}
