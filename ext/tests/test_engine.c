/* Standalone C test of the engine, the rings, the histogram and the
 * setpoint sink (protocol version 1). Built by tests/test_c_build.py with -Wall -Wextra -Werror
 * under AddressSanitizer and UBSan, and linked with --wrap=malloc (and
 * calloc, realloc, free) to prove that no tick allocates. */
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mar_clock.h"
#include "mar_engine.h"
#include "mar_hist.h"
#include "mar_ring.h"
#include "mar_rtloop.h"
#include "mar_deframer.h"
#include "mar_proto_can.h"
#include "mar_sink.h"
#include <unistd.h>

#include "mar_test.h"

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
        mar_engine_options opt = { .period = 0.02, .lead_mode = c % 3, .interp = c % 2,
                                   .record_slots = TICKS, .loudness_slots = 16,
                                   .start_holding = c % 5 == 0, .follow = c % 4 == 3,
                                   .follow_on_lost = c % 8 == 3 ? MAR_ON_LOST_HOLD : MAR_ON_LOST_FLYWHEEL };
        mar_follow_default_options(&opt.follow_opt);   /* the music drives p and r in every 4th case */
        int status;
        /* every 8th case follows with onsets (the loudness stands in for them) */
        mar_engine *e = mar_engine_create(&opt, axes, AXES, show, TICKS, loud, c % 8 == 7 ? loud : NULL, &status);
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
        for (int i = 0; i < 12; i++)    /* live frames, refused ones among them, some without onsets */
            mar_engine_push_frame(e, i == 5 ? -1.0 : uniform(0, 1), i == 7 ? -1.0 : i % 3 ? 0.5 * i : NAN);
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
        mar_lag drive[AXES];            /* the drives as the engine predicts them */
        for (int j = 0; j < AXES; j++) {
            prev_x[j] = axes[j].start;
            prev_v[j] = 0.0;
            drive[j] = (mar_lag){.tau = opt.lead_mode == MAR_LEAD_DEAD_TIME_LAG ? axes[j].time_constant : 0.0,
                                 .vmax = axes[j].limits.max_speed, .period = 0.02, .y = axes[j].start};
        }
        for (size_t k = 0; k < n; k++) {
            const double *cmd = (const double *)(rec + k * rs + sizeof(mar_record));
            const mar_record *r = (const mar_record *)(rec + k * rs);
            for (int j = 0; j < AXES; j++) {
                const mar_limits *l = &axes[j].limits;
                double v = (cmd[j] - prev_x[j]) / 0.02;
                double drive_v = drive[j].v;
                mar_lag_hold(&drive[j], cmd[j], 1);
                double tol = 1e-9 * (1.0 + fabs(l->pos_max) + fabs(l->pos_min));
                CHECK(cmd[j] >= l->pos_min - tol && cmd[j] <= l->pos_max + tol,
                      "case %d tick %zu axis %d: position %g outside [%g, %g]", c, k, j, cmd[j], l->pos_min, l->pos_max);
                CHECK(fabs(v) <= l->max_speed * (1 + 1e-9) + 1e-9,
                      "case %d tick %zu axis %d: speed %g > %g", c, k, j, v, l->max_speed);
                /* a stop ramp bounds the acceleration of the drive's predicted motion */
                double dv = r->flags & MAR_FLAG_STOPPING ? drive[j].v - drive_v : v - prev_v[j];
                CHECK(fabs(dv) <= l->max_accel * 0.02 * (1 + 1e-9) + 1e-9,
                      "case %d tick %zu axis %d: acceleration %g > %g (flags %u)", c, k, j, dv / 0.02, l->max_accel,
                      r->flags);
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
    mar_engine_options opt = { .period = 0.02, .lead_mode = MAR_LEAD_DEAD_TIME_LAG,
                               .interp = MAR_INTERP_CUBIC, .record_slots = 8, .loudness_slots = 8 };
    int status;
    mar_engine *e = mar_engine_create(&opt, &axis, 1, show, 4, loud, NULL, &status);
    CHECK(e != NULL, "create");
    CHECK(mar_engine_set_rate(e, NAN) < 0, "NaN rate accepted");
    CHECK(mar_engine_seek(e, INFINITY) < 0, "infinite seek accepted");
    CHECK(mar_engine_push_loudness(e, -1.0) < 0, "negative loudness accepted");
    CHECK(mar_engine_push_loudness(e, NAN) < 0, "NaN loudness accepted");
    CHECK(mar_engine_push_frame(e, 0.4, -1.0) < 0, "negative onset accepted");
    CHECK(mar_engine_push_frame(e, 0.4, INFINITY) < 0, "infinite onset accepted");
    CHECK(mar_engine_push_frame(e, 0.4, 2.0) == 0, "good frame refused");
    double bands[MAR_FOLLOW_MAX_BANDS + 1] = {0.1, 0.2, -0.3};
    CHECK(mar_engine_push_bands(e, 0.4, NAN, bands, 3) < 0, "negative band accepted");
    bands[2] = NAN;
    CHECK(mar_engine_push_bands(e, 0.4, NAN, bands, 3) < 0, "NaN band accepted");
    bands[2] = 0.3;
    CHECK(mar_engine_push_bands(e, 0.4, NAN, bands, MAR_FOLLOW_MAX_BANDS + 1) < 0, "too many bands accepted");
    CHECK(mar_engine_push_bands(e, 0.4, NAN, bands, 3) == 0, "good bands refused");
    CHECK(mar_engine_push_loudness(e, 0.5) == 0, "good loudness refused");
    mar_engine_step(e, 1);
    mar_record r;
    double cmd;
    CHECK(mar_engine_snapshot(e, &r, &cmd) == 0, "snapshot");
    CHECK(r.live_loudness == 0.5, "live loudness %g", r.live_loudness);    /* the newest frame */
    mar_engine_step(e, 2);
    CHECK(mar_engine_snapshot(e, &r, &cmd) == 0, "snapshot");
    CHECK(isnan(r.live_loudness), "live loudness %g on a tick without a frame", r.live_loudness);
    mar_counters cnt;
    mar_engine_counters(e, &cnt);
    CHECK(cnt.bad_input == 9, "bad inputs counted %llu", (unsigned long long)cnt.bad_input);
    mar_engine_destroy(e);

    /* refused configurations */
    double nan_show[4] = { 0, NAN, 0, 0 };
    CHECK(mar_engine_create(&opt, &axis, 1, nan_show, 4, loud, NULL, &status) == NULL, "NaN show accepted");
    mar_axis reversed = axis;
    reversed.limits.pos_min = 2;
    CHECK(mar_engine_create(&opt, &reversed, 1, show, 4, loud, NULL, &status) == NULL, "reversed limits accepted");
    mar_axis outside = axis;
    outside.start = 5;
    CHECK(mar_engine_create(&opt, &outside, 1, show, 4, loud, NULL, &status) == NULL, "start outside limits accepted");
}

/* The sink emits version-1 frames, serial and CAN, without allocating:
 * per tick a SYNC, then every axis's counts sorted by (node, channel). */
static void test_sink(void)
{
    enum { AXES = 11, TICKS = 40 };
    mar_axis axes[AXES];
    double show[AXES * TICKS], loud[TICKS];
    for (int j = 0; j < AXES; j++) {
        axes[j] = (mar_axis){ .limits = { -1, 1, 5, 50 }, .start = 0,
                              .address = { (uint8_t)(3 - j / 4), (uint8_t)(j % 4 * 2), 1000.0 + j, 7.0 } };
        for (int k = 0; k < TICKS; k++)
            show[j * TICKS + k] = 0.5 * sin(0.1 * k + j);
    }
    for (int k = 0; k < TICKS; k++)
        loud[k] = 0;
    for (int protocol = MAR_SINK_SERIAL; protocol <= MAR_SINK_CAN; protocol++) {
        for (int use_fd = 0; use_fd < 2; use_fd++) {
            mar_engine_options opt = { .period = 0.02, .lead_mode = MAR_LEAD_NONE, .interp = MAR_INTERP_LINEAR,
                                       .record_slots = TICKS, .loudness_slots = 4 };
            int status, fds[2] = { -1, -1 };
            mar_engine *e = mar_engine_create(&opt, axes, AXES, show, TICKS, loud, NULL, &status);
            CHECK(e != NULL, "create: %d", status);
            if (!e)
                return;
            mar_sink *s = mar_engine_sink(e);
            if (use_fd) {
                CHECK(pipe(fds) == 0, "pipe");
                CHECK(mar_sink_set(s, MAR_SINK_FD, fds[1], 0, protocol) == 0, "fd sink");
            } else {
                CHECK(mar_sink_set(s, MAR_SINK_RING, -1, 64, protocol) == 0, "ring sink");
            }
            long before = allocations;
            mar_engine_step(e, TICKS);
            CHECK(allocations == before, "sink ticks allocated %ld times", allocations - before);
            size_t rs = mar_engine_record_size(e);
            unsigned char *rec = malloc(rs * TICKS);
            CHECK(mar_engine_drain_records(e, rec, TICKS) == TICKS, "records");
            /* everything the sink produced, in one buffer */
            size_t cap = TICKS * (s->frame_cap + 4), len = 0;
            uint8_t *buf = malloc(cap), *slot = malloc(s->ring.slot_size ? s->ring.slot_size : 1);
            if (use_fd) {
                ssize_t r;
                while (len < cap && (r = read(fds[0], buf + len, cap - len)) > 0) {
                    len += (size_t)r;
                    if (len == atomic_load(&s->bytes))
                        break;
                }
            } else {
                while (mar_ring_pop(&s->ring, slot, 1) == 1) {
                    uint32_t n;
                    memcpy(&n, slot, 4);
                    memcpy(buf + len, slot + 4, n);
                    len += n;
                }
            }
            CHECK(len == atomic_load(&s->bytes), "%zu bytes of %llu", len, (unsigned long long)atomic_load(&s->bytes));
            /* decode: count SYNCs, check each tick's entries against the record */
            static mar_deframer d;
            static mar_can_rx rx;
            mar_deframer_init(&d);
            mar_can_rx_init(&rx);
            int ticks = 0;
            size_t got = 0;
            mar_setpoint_entry tick_entries[AXES];
            mar_msg m;
            for (size_t at = 0; at < len;) {
                int r;
                if (protocol == MAR_SINK_SERIAL) {
                    r = mar_deframer_push(&d, buf[at++], &m);
                } else {
                    mar_can_frame f = { (uint16_t)(buf[at] | buf[at + 1] << 8), buf[at + 4], { 0 } };
                    memcpy(f.data, buf + at + 8, 8);
                    at += MAR_CAN_RECORD_BYTES;
                    r = mar_can_rx_feed(&rx, &f, &m);
                }
                CHECK(r >= 0, "undecodable sink output: %d", r);
                if (r != 1)
                    continue;
                if (m.type == MAR_MSG_SYNC) {
                    CHECK(got == (ticks ? AXES : 0), "tick %d had %zu entries", ticks - 1, got);
                    CHECK(m.seq == (uint32_t)ticks, "SYNC %u, expected %d", (unsigned)m.seq, ticks);
                    ticks++;
                    got = 0;
                    continue;
                }
                CHECK(m.type == MAR_MSG_SETPOINT && m.seq == (uint32_t)(ticks - 1), "setpoint tick");
                for (size_t i = 0; i < m.setpoint.n && got < AXES; i++)
                    tick_entries[got++] = m.setpoint.entry[i];
                if (got == AXES) {      /* sorted by address; counts as the record says */
                    const double *cmd = (const double *)(rec + rs * (size_t)(ticks - 1) + sizeof(mar_record));
                    for (size_t i = 0; i < AXES; i++) {
                        int j = (int)(3 - tick_entries[i].node) * 4 + tick_entries[i].channel / 2;
                        CHECK(i == 0 || tick_entries[i - 1].node < tick_entries[i].node
                              || tick_entries[i - 1].channel < tick_entries[i].channel, "order");
                        CHECK(j >= 0 && j < AXES && tick_entries[i].counts == mar_counts(&axes[j].address, cmd[j]),
                              "tick %d entry %zu", ticks - 1, i);
                    }
                }
            }
            CHECK(ticks == TICKS && got == AXES, "protocol %d fd %d: %d ticks", protocol, use_fd, ticks);
            free(buf);
            free(slot);
            free(rec);
            if (use_fd) {
                close(fds[0]);
                close(fds[1]);
            }
            mar_engine_destroy(e);
        }
    }
    /* addresses a protocol cannot carry are refused */
    mar_axis bad = axes[0];
    double one[2] = { 0, 0 };
    int status;
    bad.address.node = 0;
    mar_engine_options opt = { .period = 0.02, .lead_mode = MAR_LEAD_NONE, .interp = MAR_INTERP_LINEAR,
                               .loudness_slots = 4 };
    mar_engine *e = mar_engine_create(&opt, &bad, 1, one, 2, one, NULL, &status);
    CHECK(mar_sink_set(mar_engine_sink(e), MAR_SINK_RING, -1, 4, MAR_SINK_CAN) == -22, "node 0 on CAN");
    CHECK(mar_sink_set(mar_engine_sink(e), MAR_SINK_RING, -1, 4, 7) == -22, "unknown protocol");
    CHECK(mar_sink_set(mar_engine_sink(e), MAR_SINK_RING, -1, 4, MAR_SINK_SERIAL) == 0, "node 0 on serial");
    mar_engine_destroy(e);
}

/* The music of the lost-music tests: a wandering level with notes on it
 * [full scale], and a 6 s sine to show [unit]. */
static void lost_music(double *show, double *loud, int n)
{
    double level = 0.0;
    for (int k = 0; k < n; k++) {
        level = 0.98 * level + uniform(-1.0, 1.0);
        loud[k] = 0.01 * pow(10.0, (2.0 * level + (k % 25 < 4 ? 15.0 : 0.0)) / 20.0);
        show[k] = 0.5 * sin(6.283185307179586 * k / 300.0);
    }
}

static mar_axis lost_axis(const double *show)
{
    mar_axis axis = { .limits = { -1, 1, 5, 100 }, .start = show[500], .address = { 1, 0, 100, 0 } };
    return axis;
}

/* One axis following loud from an unknown start, 2048 records; NULL (a
 * failed check) if it cannot be made. */
static mar_engine *following_engine(const mar_axis *axis, const double *show, const double *loud, size_t n,
                                    int hold)
{
    mar_engine_options opt = { .period = 0.02, .lead_mode = MAR_LEAD_NONE, .interp = MAR_INTERP_LINEAR,
                               .record_slots = 2048, .loudness_slots = 16, .follow = 1,
                               .follow_cue = NAN,
                               .follow_on_lost = hold ? MAR_ON_LOST_HOLD : MAR_ON_LOST_FLYWHEEL };
    mar_follow_default_options(&opt.follow_opt);
    int status;
    mar_engine *e = mar_engine_create(&opt, axis, 1, show, n, loud, NULL, &status);
    CHECK(e != NULL, "create: %d", status);
    return e;
}

/* The music lost: the live frames follow the stored loudness from a known
 * start (a seek), then turn to noise that matches no place, so the follower
 * ends up SEARCHING after it had a place. MAR_FLAG_UNFOLLOWED marks exactly
 * those ticks; with MAR_ON_LOST_HOLD the position stands where the last
 * followed tick had it (rate 0), with the flywheel it runs on at the last
 * rate; a seek gives the follower a place again, and after a hold the
 * figure blends there (MAR_FLAG_MOVING). No tick allocates. */
static void test_on_lost(void)
{
    enum { TICKS = 3000, FOLLOWED = 600, NOISE = 600, AFTER = 100 };
    static double show[TICKS], loud[TICKS];
    lost_music(show, loud, TICKS);
    mar_axis axis = lost_axis(show);
    for (int hold = 0; hold <= 1; hold++) {
        mar_engine *e = following_engine(&axis, show, loud, TICKS, hold);
        if (!e)
            return;
        size_t rs = mar_engine_record_size(e);
        unsigned char *buf = malloc(rs * 2048);
        long before = allocations;
        mar_engine_step(e, 20);                 /* no music yet: searching, no place, not unfollowed */
        mar_engine_seek(e, 500.0);
        for (int k = 0; k < FOLLOWED + NOISE; k++) {
            mar_engine_push_loudness(e, k < FOLLOWED ? loud[500 + k] : 0.01 * pow(10.0, uniform(-1.0, 1.0)));
            mar_engine_step(e, 1);
        }
        mar_engine_seek(e, 2000.0);
        for (int k = 0; k < AFTER; k++) {
            mar_engine_push_loudness(e, loud[2000 + k]);
            mar_engine_step(e, 1);
        }
        CHECK(allocations == before, "on_lost %d: ticks allocated %ld times", hold, allocations - before);
        size_t n = mar_engine_drain_records(e, buf, 2048);
        CHECK(n == 20 + FOLLOWED + NOISE + AFTER, "recorded %zu", n);
        int had_place = 0, lost = 0, first_lost = -1, rejoined = -1;
        mar_record prev = { 0 };
        for (size_t i = 0; i < n; i++) {
            mar_record r;
            memcpy(&r, buf + i * rs, sizeof r);
            int unfollowed = had_place && r.follow_state == MAR_FOLLOW_SEARCHING;
            CHECK(!!(r.flags & MAR_FLAG_UNFOLLOWED) == unfollowed, "on_lost %d tick %zu: flags 0x%x, state %d",
                  hold, i, r.flags, r.follow_state);
            if (unfollowed) {
                if (first_lost < 0)
                    first_lost = (int)i;
                lost++;
                if (hold)
                    CHECK(r.position == prev.position && r.rate == 0.0, "on_lost hold tick %zu: p %g (was %g), r %g",
                          i, r.position, prev.position, r.rate);
                else if (first_lost < (int)i)   /* the last rate, and not standing still */
                    CHECK(fabs(r.position - prev.position - prev.rate) < 1e-9 && r.rate == prev.rate
                          && r.rate > 0.5, "on_lost flywheel tick %zu: p %g (was %g), r %g (was %g)",
                          i, r.position, prev.position, r.rate, prev.rate);
            } else if (prev.flags & MAR_FLAG_UNFOLLOWED && rejoined < 0) {
                rejoined = (int)i;
                if (hold)
                    CHECK(r.flags & MAR_FLAG_MOVING, "on_lost hold: no blend back in at tick %zu", i);
            }
            had_place |= r.follow_state != MAR_FOLLOW_SEARCHING;
            prev = r;
        }
        CHECK(lost > 50 && first_lost > 20 + FOLLOWED, "on_lost %d: %d ticks unfollowed from %d", hold, lost, first_lost);
        CHECK(rejoined == 20 + FOLLOWED + NOISE, "on_lost %d: followed again at tick %d", hold, rejoined);
        free(buf);
        mar_engine_destroy(e);
    }
    mar_engine_options bad = { .period = 0.02, .loudness_slots = 4, .follow = 1, .follow_on_lost = 2 };
    mar_follow_default_options(&bad.follow_opt);
    int status;
    CHECK(mar_engine_create(&bad, &axis, 1, show, TICKS, loud, NULL, &status) == NULL && status == -22,
          "unknown on_lost accepted");
}

/* The source lost (mar_engine_source_lost) while the follower follows: from
 * the next tick to the end every record carries MAR_FLAG_SOURCE_LOST and
 * MAR_FLAG_UNFOLLOWED, none before; the frames that still come do not bring
 * the show back. Hold stands at the last followed position, the flywheel
 * runs on at the last followed rate; a seek places the show (a blend). An
 * engine without a follower only flags it. No tick allocates. */
static void test_source_lost(void)
{
    enum { TICKS = 3000, FOLLOWED = 500, LOST_AT = 20 + FOLLOWED, AFTER = 300, SEEK = 2000 };
    static double show[TICKS], loud[TICKS];
    lost_music(show, loud, TICKS);
    mar_axis axis = lost_axis(show);
    for (int hold = 0; hold <= 1; hold++) {
        mar_engine *e = following_engine(&axis, show, loud, TICKS, hold);
        if (!e)
            return;
        size_t rs = mar_engine_record_size(e);
        unsigned char *buf = malloc(rs * 2048);
        long before = allocations;
        mar_engine_step(e, 20);
        mar_engine_seek(e, 500.0);
        for (int k = 0; k < FOLLOWED + AFTER; k++) {
            if (20 + k == LOST_AT)
                mar_engine_source_lost(e);      /* applies at tick LOST_AT */
            mar_engine_push_loudness(e, loud[500 + k]);     /* the frames go on: stale, not trusted */
            mar_engine_step(e, 1);
        }
        mar_engine_seek(e, (double)SEEK);
        mar_engine_step(e, 100);
        CHECK(allocations == before, "source lost %d: ticks allocated %ld times", hold, allocations - before);
        size_t n = mar_engine_drain_records(e, buf, 2048);
        CHECK(n == 20 + FOLLOWED + AFTER + 100, "recorded %zu", n);
        mar_record r, prev = { 0 }, followed = { 0 };
        for (size_t i = 0; i < n; i++) {
            memcpy(&r, buf + i * rs, sizeof r);
            int lost = (int)i >= LOST_AT;
            CHECK(!!(r.flags & MAR_FLAG_SOURCE_LOST) == lost && (!lost || (r.flags & MAR_FLAG_UNFOLLOWED)),
                  "source lost %d tick %zu: flags 0x%x", hold, i, r.flags);
            if ((int)i == LOST_AT - 1) {
                followed = r;
                CHECK(r.follow_state == MAR_FOLLOW_LOCKED && r.rate > 0.9, "not locked before the loss: state %d",
                      r.follow_state);
            }
            if (lost && (int)i < 20 + FOLLOWED + AFTER) {
                if (hold)
                    CHECK(r.position == followed.position && r.rate == 0.0, "hold tick %zu: p %g r %g",
                          i, r.position, r.rate);
                else
                    CHECK(r.rate == followed.rate && fabs(r.position - prev.position - followed.rate) < 1e-9,
                          "flywheel tick %zu: p %g (was %g), r %g (last %g)", i, r.position, prev.position,
                          r.rate, followed.rate);
            }
            if ((int)i == 20 + FOLLOWED + AFTER)
                CHECK(r.position == SEEK && (r.flags & MAR_FLAG_MOVING), "seek after the loss: p %g, flags 0x%x",
                      r.position, r.flags);
            prev = r;
        }
        free(buf);
        mar_engine_destroy(e);
    }
    mar_engine_options plain = { .period = 0.02, .lead_mode = MAR_LEAD_NONE, .interp = MAR_INTERP_LINEAR,
                                 .record_slots = 64, .loudness_slots = 4 };
    int status;
    mar_engine *e = mar_engine_create(&plain, &axis, 1, show, TICKS, loud, NULL, &status);
    mar_engine_step(e, 3);
    mar_engine_source_lost(e);
    mar_engine_source_lost(e);
    mar_engine_step(e, 3);
    mar_record recs[6];
    size_t rs = mar_engine_record_size(e), n;
    unsigned char pbuf[6 * (sizeof(mar_record) + 2 * sizeof(double))];   /* 1 axis: command, excess */
    CHECK(rs * 6 == sizeof pbuf, "record of %zu bytes", rs);
    n = mar_engine_drain_records(e, pbuf, 6);
    for (size_t i = 0; i < n; i++) {
        memcpy(&recs[i], pbuf + i * rs, sizeof recs[i]);
        CHECK(!!(recs[i].flags & MAR_FLAG_SOURCE_LOST) == (i >= 3) && !(recs[i].flags & MAR_FLAG_UNFOLLOWED)
              && recs[i].position == (double)i, "no follower, tick %zu: flags 0x%x, p %g", i, recs[i].flags,
              recs[i].position);
    }
    CHECK(n == 6, "recorded %zu", n);
    mar_engine_destroy(e);
}

/* The fault reactions in the tick: a silent node (continue, stop, hold,
 * estop), the overrun threshold and a vanished descriptor. From the tick
 * after the news every record says so; a stop brakes every axis at its
 * acceleration limit to rest inside its position limits and stays latched;
 * a hold blends back in when the nodes answer; no tick allocates. */
static void test_faults(void)
{
    enum { N = 400, AXES = 3, AT = 60, REC = 512 };
    static double show[AXES * N], loud[N];
    mar_axis axes[AXES];
    for (int j = 0; j < AXES; j++) {
        axes[j] = (mar_axis){ .limits = { -1, 1, 1.0 + j, 4.0 + 3 * j }, .start = 0,
                              .address = { (uint8_t)(1 + j), 0, 100, 0 } };
        for (int k = 0; k < N; k++)
            show[j * N + k] = 0.5 * sin(3.141592653589793 * k * 0.02 + j);
        axes[j].start = show[j * N];
    }
    for (int k = 0; k < N; k++)
        loud[k] = 0;
    for (int kind = 0; kind < 6; kind++) {      /* reactions 0..3, overruns, descriptor gone */
        int reaction = kind <= MAR_FAULT_ESTOP ? kind : kind == 5 ? MAR_FAULT_STOP : MAR_FAULT_CONTINUE;
        mar_engine_options opt = { .period = 0.02, .lead_mode = MAR_LEAD_NONE, .interp = MAR_INTERP_CUBIC,
                                   .record_slots = REC, .loudness_slots = 4, .on_silent_node = reaction,
                                   .max_overruns = kind == 4 ? 3 : 0 };
        int status;
        mar_engine *e = mar_engine_create(&opt, axes, AXES, show, N, loud, NULL, &status);
        CHECK(e != NULL, "faults %d: create %d", kind, status);
        if (!e)
            continue;
        size_t rs = mar_engine_record_size(e);
        unsigned char *buf = malloc(rs * REC);
        long before = allocations;
        mar_engine_step(e, AT);
        if (kind == 4) {
            mar_engine_count_overruns(e, 2);
            mar_engine_step(e, 5);
            mar_engine_count_overruns(e, 1);
        } else if (kind == 5) {
            mar_sink_set(mar_engine_sink(e), MAR_SINK_FD, 1000, 0, MAR_SINK_SERIAL);  /* not open: EBADF */
        } else {
            mar_engine_set_node_alarms(e, 0x6, 0x2);
        }
        int from = kind == 4 ? AT + 5 : kind == 5 ? AT + 1 : AT;   /* the first tick that knows */
        mar_engine_step(e, 100);
        if (kind <= MAR_FAULT_ESTOP)
            mar_engine_set_node_alarms(e, 0, 0);        /* the node answers again */
        mar_engine_step(e, 100);
        CHECK(allocations == before, "faults %d: ticks allocated %ld times", kind, allocations - before);
        size_t n = mar_engine_drain_records(e, buf, REC);
        CHECK(n == AT + 200 + (kind == 4 ? 5 : 0), "faults %d: recorded %zu", kind, n);
        mar_record r;
        double cmd[AXES], prev[AXES], v[AXES] = { 0 };
        int rest_at = -1, stops = kind == MAR_FAULT_STOP || kind == MAR_FAULT_ESTOP || kind >= 4;
        int back = kind <= MAR_FAULT_ESTOP ? from + 100 : (int)n;     /* first tick with the node answering */
        double held = 0;                        /* the playback position at `from` */
        double slowest = 0;                     /* ticks the limits need to brake from the speeds at `from` */
        for (size_t i = 0; i < n; i++) {
            int t = (int)i;
            memcpy(&r, buf + i * rs, sizeof r);
            memcpy(cmd, buf + i * rs + sizeof r, sizeof cmd);
            int silent = kind == 5 ? t >= from : kind <= MAR_FAULT_ESTOP && t >= from && t < back;
            CHECK(!!(r.flags & MAR_FLAG_NODE_SILENT) == silent, "faults %d tick %d: flags 0x%x", kind, t, r.flags);
            CHECK(!!(r.flags & MAR_FLAG_FAULT_STOP) == (stops && t >= from), "faults %d tick %d: flags 0x%x",
                  kind, t, r.flags);
            CHECK(!!(r.flags & MAR_FLAG_FAULT_HOLD) == (kind == MAR_FAULT_HOLD && silent),
                  "faults %d tick %d: flags 0x%x", kind, t, r.flags);
            CHECK(!!(r.flags & MAR_FLAG_OVERRUNS) == (kind == 4 && t >= from), "faults %d tick %d: flags 0x%x",
                  kind, t, r.flags);
            CHECK(!!(r.flags & MAR_FLAG_LINK_LOST) == (kind == 5 && t >= from), "faults %d tick %d: flags 0x%x",
                  kind, t, r.flags);
            if (kind <= MAR_FAULT_ESTOP)
                CHECK(r.node_alarms == (t >= from && t < back ? 0x6u : 0u), "faults %d tick %d: alarms 0x%x",
                      kind, t, r.node_alarms);
            double moved = 0;
            for (int j = 0; j < AXES; j++) {
                const mar_limits *l = &axes[j].limits;
                double vj = i ? (cmd[j] - prev[j]) / 0.02 : 0;
                CHECK(cmd[j] >= l->pos_min && cmd[j] <= l->pos_max, "faults %d: outside", kind);
                if (i && t >= from && (stops || (kind == MAR_FAULT_HOLD && t < back))) {
                    CHECK(fabs(vj - v[j]) <= l->max_accel * 0.02 * (1 + 1e-9), "faults %d tick %d axis %d: "
                          "accel %g > %g", kind, t, j, (vj - v[j]) / 0.02, l->max_accel);
                    CHECK(fabs(vj) <= fabs(v[j]) + 1e-12, "faults %d tick %d axis %d: speeds up", kind, t, j);
                }
                if (t == from)
                    slowest = fmax(slowest, fabs(v[j]) / (l->max_accel * 0.02));
                moved = fmax(moved, fabs(vj));
                v[j] = vj;
                prev[j] = cmd[j];
            }
            if (t >= from && rest_at < 0 && moved == 0)
                rest_at = t;
            if (stops && rest_at >= 0)
                CHECK(moved == 0, "faults %d tick %d: moves after rest (latched)", kind, t);
            if (kind == MAR_FAULT_CONTINUE && i)
                CHECK(r.position == (double)t, "continue: tick %d at %g", t, r.position);
            if (t == from)
                held = r.position;
            if (kind == MAR_FAULT_HOLD && t > from && t < back)
                CHECK(r.position == held && (r.flags & (MAR_FLAG_MOVING | MAR_FLAG_HOLDING)),
                      "hold tick %d: p %g (held %g), flags 0x%x", t, r.position, held, r.flags);
            if (kind == MAR_FAULT_HOLD && t >= back + 60)    /* blended back in: playing on from there */
                CHECK(!(r.flags & (MAR_FLAG_MOVING | MAR_FLAG_HOLDING)) && r.position > held,
                      "hold tick %d: p %g (held %g), flags 0x%x", t, r.position, held, r.flags);
        }
        if (kind != MAR_FAULT_CONTINUE)
            CHECK(rest_at >= from && rest_at - from <= (int)ceil(slowest) + 2, "faults %d: at rest %d ticks after "
                  "the news, the limits need %.1f", kind, rest_at - from, slowest);
        free(buf);
        mar_engine_destroy(e);
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
    mar_engine_options opt = { .period = 0.005, .lead_mode = MAR_LEAD_DEAD_TIME_LAG,
                               .interp = MAR_INTERP_CUBIC, .record_slots = 256, .loudness_slots = 4 };
    int status;
    mar_engine *e = mar_engine_create(&opt, &axis, 1, show, 100, loud, NULL, &status);
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

/* The show's clock: on 200 random music clocks (corrections of up to a
 * tick and rate steps of up to 4 % every second) it settles on a steady
 * rate without lag, its rate never jumps (it changes by less than 0.004 a
 * tick; 0.003 here) nor strays far from the music's (0.06 here); from the
 * cue it catches a music 12.5 ticks ahead up at catch_up faster (4 s), and
 * the periods an overrun missed too. */
static void test_clock(void)
{
    const double T = 0.02;
    double worst_change = 0.0, worst_off = 0.0;        /* [ticks/tick^2], [1] */
    for (int c = 0; c < 200; c++) {
        double rate = uniform(0.9, 1.1), pos = uniform(0.0, 100.0);
        mar_clock k;
        mar_clock_set(&k, pos, rate);
        for (int i = 0; i < 600; i++) {
            pos += rate;
            if (i % 50 == 25) {                         /* a measurement corrects the music */
                pos += uniform(-1.0, 1.0);
                rate += uniform(-0.04, 0.04);
            }
            double before = k.rate;
            mar_clock_follow(&k, pos, rate, T, 0.1);
            double change = fabs(k.rate - before), off = fabs(k.rate - rate);
            worst_change = change > worst_change ? change : worst_change;
            worst_off = off > worst_off ? off : worst_off;
        }
        for (int i = 0; i < 300; i++) {                 /* then steady */
            pos += rate;
            mar_clock_follow(&k, pos, rate, T, 0.1);
        }
        CHECK(fabs(k.position - pos) < 1e-3 && fabs(k.rate - rate) < 1e-4,
              "clock %d settles: off by %g ticks, rate %g", c, k.position - pos, k.rate - rate);
    }
    CHECK(worst_change < 0.004, "clock rate change per tick %g", worst_change);
    CHECK(worst_off < 0.1, "clock rate off the music's by %g", worst_off);
    /* the cue: standing at 0, the music 12.5 ticks ahead at rate 1 */
    mar_clock k;
    mar_clock_set(&k, 0.0, 0.0);
    double pos = 12.5, fastest = 0.0;
    int caught = -1;
    for (int i = 0; i < 500; i++) {
        pos += 1.0;
        mar_clock_follow(&k, pos, 1.0, T, 0.1);
        fastest = k.rate > fastest ? k.rate : fastest;
        if (caught < 0 && fabs(pos - k.position) < 0.1)
            caught = i;
    }
    CHECK(k.rate == k.rate && fastest <= 1.1 + 1e-3 && caught > 100 && caught < 300,
          "cue: fastest %g, caught up at tick %d", fastest, caught);
    /* an overrun of 4 periods: the music 4 ticks on, the clock one, then it
     * catches the 3 up without a jump of its rate */
    mar_clock_set(&k, 10.0, 1.0);
    pos = 14.0;
    mar_clock_follow(&k, pos, 1.0, T, 0.1);
    CHECK(k.position == 11.0, "overrun: the clock moved %g", k.position - 10.0);
    double most = 0.0, before = k.rate;
    for (int i = 0; i < 300; i++) {
        pos += 1.0;
        mar_clock_follow(&k, pos, 1.0, T, 0.1);
        most = fabs(k.rate - before) > most ? fabs(k.rate - before) : most;
        before = k.rate;
    }
    CHECK(most < 0.004 && fabs(pos - k.position) < 1e-3, "overrun: rate step %g, off %g", most,
          pos - k.position);
}

/* A GOTO reaches its pose. Overruns (periods elapsed between ticks):
 * its profile runs a period per tick, so its commands are those of the
 * same move without overruns, later (run in wall time, the profile ended
 * before the limited commands arrived and the hold stood short: a "home"
 * under load stopped short of home). Near a position limit the limiter's
 * sampled braking bound holds the commands back (0.4-2.9 mm off the pose
 * on 4 of 600 random axes of this kind): the move is planned again. Random axes
 * and poses, one engine ticking a period at a time and one missing up to
 * 3 periods per tick for the first 6 s: every command within the limits,
 * at most a tick's worth of speed apart, the same commands tick by tick,
 * and the pose at the end. */
static void test_moves_arrive_after_overruns(int cases)
{
    enum { AXES = 3, TICKS = 4, RUN = 1200, OVERRUN = 300 };   /* 24 s: the slowest move needs 16 s */
    for (int c = 0; c < cases; c++) {
        mar_axis axes[AXES];
        double show[AXES * TICKS], loud[TICKS] = {0.0}, pose[AXES];
        for (int j = 0; j < AXES; j++) {
            double lo = uniform(-2, 0), hi = lo + uniform(0.5, 3);
            axes[j] = (mar_axis){
                .limits = { lo, hi, uniform(0.2, 3), uniform(1, 20) },
                .dead_time = uniform(0, 0.1), .time_constant = uniform(0, 0.2),
                .start = uniform(lo, hi),
                .address = { (uint8_t)j, 0, 1000.0, 0.0 },
            };
            for (int k = 0; k < TICKS; k++)
                show[j * TICKS + k] = axes[j].start;
            pose[j] = uniform(lo, hi);
        }
        mar_engine_options opt = { .period = 0.02, .record_slots = RUN, .loudness_slots = 16, .start_holding = 1 };
        unsigned char *rec[2] = {NULL, NULL};
        size_t rs = 0, n[2] = {0, 0};
        int64_t missed[OVERRUN];
        for (int k = 0; k < OVERRUN; k++)
            missed[k] = (int64_t)uniform(0, 4);                      /* periods missed before tick k */
        for (int run = 0; run < 2; run++) {
            int status;
            mar_engine *e = mar_engine_create(&opt, axes, AXES, show, TICKS, loud, NULL, &status);
            CHECK(e != NULL, "create failed: %d", status);
            if (!e)
                break;
            rs = mar_engine_record_size(e);
            rec[run] = malloc(rs * RUN);
            mar_engine_request(e, MAR_REQ_GOTO, pose, c % 2);
            int64_t periods = 0;
            for (int k = 0; k < RUN; k++) {
                int64_t elapsed = 1 + (run && k < OVERRUN ? missed[k] : 0);
                periods += elapsed;
                mar_engine_tick(e, periods * 20000000, elapsed);
            }
            n[run] = mar_engine_drain_records(e, rec[run], RUN);
            CHECK(n[run] == RUN, "recorded %zu of %d ticks", n[run], RUN);
            mar_engine_destroy(e);
        }
        for (int j = 0; j < AXES && n[0] == RUN && n[1] == RUN; j++) {
            const mar_limits *l = &axes[j].limits;
            double prev = axes[j].start, tol = 1e-9 * (1.0 + fabs(l->pos_max) + fabs(l->pos_min));
            for (size_t k = 0; k < RUN; k++) {
                double x = ((const double *)(rec[1] + k * rs + sizeof(mar_record)))[j];
                double x0 = ((const double *)(rec[0] + k * rs + sizeof(mar_record)))[j];
                CHECK(x >= l->pos_min - tol && x <= l->pos_max + tol, "case %d tick %zu axis %d: %g outside", c, k, j, x);
                CHECK(fabs(x - prev) <= l->max_speed * 0.02 * (1 + 1e-9) + 1e-12,
                      "case %d tick %zu axis %d: step %g over a tick's worth", c, k, j, x - prev);
                CHECK(fabs(x - x0) <= tol, "case %d tick %zu axis %d: %.9g with overruns, %.9g without",
                      c, k, j, x, x0);
                prev = x;
            }
            CHECK(fabs(prev - pose[j]) <= tol, "case %d axis %d: ends at %.9g, asked %.9g", c, j, prev, pose[j]);
        }
        free(rec[0]);
        free(rec[1]);
    }
}

int main(void)
{
    signal(SIGPIPE, SIG_IGN);
    test_limits_random(300);
    test_bad_inputs();
    test_sink();
    test_on_lost();
    test_source_lost();
    test_faults();
    test_ring_and_hist();
    test_rtloop();
    test_clock();
    test_moves_arrive_after_overruns(100);
    if (failures) {
        fprintf(stderr, "%d checks failed\n", failures);
        return 1;
    }
    printf("C engine tests passed\n");
    return 0;
}
