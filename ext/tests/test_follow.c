/* Standalone C test of the music follower (mar_follow*.c: the follower,
 * its correlation at lags and its Kalman filter, each on its own first). Built by
 * tests/test_follow.py with -Wall -Wextra -Wpedantic -Werror under
 * AddressSanitizer and UBSan, and linked with --wrap=malloc (and calloc,
 * realloc, free) to prove that no step allocates. */
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mar_follow.h"
#include "mar_follow_corr.h"
#include "mar_follow_deck.h"
#include "mar_follow_kf.h"

#include "mar_test.h"

/* A loudness curve with beats and phrases: linear, >= 0. */
static void music(double *x, size_t n, double seed)
{
    for (size_t i = 0; i < n; i++) {
        double t = (double)i * 0.02;                              /* [s] */
        double beat = fmod(t * 2.1 + seed, 1.0);                  /* about 126 bpm */
        double phrase = 0.5 + 0.4 * sin(0.37 * t + seed) * sin(0.11 * t + 2.0 * seed);
        x[i] = phrase * (0.05 + exp(-beat * 9.0)) * (1.0 + 0.3 * uniform(-1.0, 1.0));
    }
}

/* Live frames of the stored music played at rate from start [stored ticks]. */
static double live_at(const double *s, size_t n, double start, double rate, size_t k)
{
    double x = start + rate * ((double)k + 0.5) - 0.5;           /* stored frame at this frame's centre */
    if (x < 0.0 || x >= (double)(n - 1))
        return 0.0;
    size_t j = (size_t)x;
    double fr = x - (double)j;
    return s[j] + fr * (s[j + 1] - s[j]);
}

static void test_bad_options(void)
{
    double stored[100];
    for (int i = 0; i < 100; i++)
        stored[i] = 0.1 + 0.05 * (double)(i % 7);
    mar_follow_options o;
    int status = 0;
    mar_follow_default_options(&o);
    mar_follow *f = mar_follow_create(&o, stored, 100, &status);
    CHECK(f && status == 0, "defaults refused: %d", status);
    mar_follow_destroy(f);

    struct { const char *what; mar_follow_options o; } bad[16];
    int nb = 0;
    for (int i = 0; i < 16; i++)
        mar_follow_default_options(&bad[i].o);
    bad[nb].what = "mode"; bad[nb++].o.mode = 7;
    bad[nb].what = "rate_min > 1"; bad[nb++].o.rate_min = 1.5;
    bad[nb].what = "rate_max < 1"; bad[nb++].o.rate_max = 0.5;
    bad[nb].what = "rate NaN"; bad[nb++].o.rate_min = NAN;
    bad[nb].what = "window < min"; bad[nb++].o.window = 0.5;
    bad[nb].what = "window 3 ticks"; bad[nb].o.min_window = 0.08; bad[nb++].o.window = 0.06;
    bad[nb].what = "search block 0"; bad[nb++].o.search_block = 0.0;
    bad[nb].what = "search window 5 blocks"; bad[nb++].o.search_window = 0.4;
    bad[nb].what = "budget 0"; bad[nb++].o.search_budget = 0;
    bad[nb].what = "threshold"; bad[nb++].o.lock_threshold = 1.5;
    bad[nb].what = "pause_after < 0"; bad[nb++].o.pause_after = -0.1;
    bad[nb].what = "latency inf"; bad[nb++].o.latency = INFINITY;
    bad[nb].what = "rate step 0"; bad[nb++].o.rate_step = 0.0;
    bad[nb].what = "lock window > verify"; bad[nb++].o.lock_window = 6.0;
    bad[nb].what = "tick period 0"; bad[nb++].o.tick_period = 0.0;
    bad[nb].what = "tick period NaN"; bad[nb++].o.tick_period = NAN;
    for (int i = 0; i < nb; i++) {
        status = 0;
        f = mar_follow_create(&bad[i].o, stored, 100, &status);
        CHECK(!f && status < 0, "bad option %s accepted", bad[i].what);
        mar_follow_destroy(f);
    }
    /* the music refused: none, too few or too many bands, a negative band level */
    static double rows[100 * (MAR_FOLLOW_MAX_BANDS + 1)];
    for (size_t i = 0; i < sizeof rows / sizeof rows[0]; i++)
        rows[i] = 0.01 * (double)(i % 13);
    status = 0;
    CHECK(!mar_follow_create_music(&o, NULL, &status) && status == -EINVAL, "no music accepted");
    const mar_follow_music bad_music[] = {
        {.loudness = stored, .bands = rows, .n_bands = 0, .n = 100},
        {.loudness = stored, .bands = rows, .n_bands = MAR_FOLLOW_MAX_BANDS + 1, .n = 100},
        {.loudness = NULL, .n = 100},
    };
    for (size_t i = 0; i < sizeof bad_music / sizeof bad_music[0]; i++) {
        status = 0;
        CHECK(!mar_follow_create_music(&o, &bad_music[i], &status) && status == -EINVAL, "bad music %zu accepted", i);
    }
    const mar_follow_music six = {.loudness = stored, .bands = rows, .n_bands = 6, .n = 100};
    f = mar_follow_create_music(&o, &six, &status);
    CHECK(f && status == 0, "six bands refused: %d", status);
    mar_follow_destroy(f);
    rows[6 * 50 + 3] = -0.1;
    CHECK(!mar_follow_create_music(&o, &six, &status) && status == -EINVAL, "a negative band level accepted");
    rows[6 * 50 + 3] = 0.1;
    /* a fine rate grid is widened to MAX_RATES rates, not refused; other
     * tick periods convert the times */
    mar_follow_options fine = o;
    fine.rate_step = 0.002;      /* 101 rates over 0.9 .. 1.1 */
    f = mar_follow_create(&fine, stored, 100, &status);
    CHECK(f && status == 0, "fine rate grid refused: %d", status);
    mar_follow_destroy(f);
    const double periods[] = {0.005, 0.010, 0.025, 0.040};
    for (size_t i = 0; i < sizeof periods / sizeof periods[0]; i++) {
        mar_follow_options other = o;
        other.tick_period = periods[i];
        f = mar_follow_create(&other, stored, 100, &status);
        CHECK(f && status == 0, "defaults at %g s ticks refused: %d", periods[i], status);
        mar_follow_destroy(f);
    }
    double with_nan[4] = {0.1, NAN, 0.2, 0.3}, negative[4] = {0.1, -0.1, 0.2, 0.3};
    status = 0;
    CHECK(!mar_follow_create(&o, with_nan, 4, &status) && status < 0, "NaN stored accepted");
    status = 0;
    CHECK(!mar_follow_create(&o, negative, 4, &status) && status < 0, "negative stored accepted");
    status = 0;
    CHECK(!mar_follow_create(&o, stored, 1, &status) && status < 0, "one stored frame accepted");
    double level[4] = {0.1, 0.2, 0.3, 0.4};
    status = 0;
    CHECK(!mar_follow_create_onsets(&o, level, with_nan, 4, &status) && status < 0, "NaN onset accepted");
    status = 0;
    CHECK(!mar_follow_create_onsets(&o, level, negative, 4, &status) && status < 0, "negative onset accepted");
    o.onset_weight = -1.0;
    status = 0;
    CHECK(!mar_follow_create_onsets(&o, level, level, 4, &status) && status < 0, "negative onset weight accepted");
}

/* Random stored music, random live input (music, silence, noise, NaN,
 * negative, infinite; with and without onsets, and bad onsets): every
 * output sane, no step allocates. */
static void test_random_inputs(int cases)
{
    enum { N = 3000, STEPS = 2500 };
    static double stored[N], stored_onset[N];
    for (int c = 0; c < cases; c++) {
        music(stored, N, (double)c);
        int onsets = c % 4 < 2;
        for (size_t i = 0; i < N; i++)
            stored_onset[i] = fabs(sin(0.37 * (double)i + (double)c));
        mar_follow_options o;
        mar_follow_default_options(&o);
        o.mode = c % 3 == 2 ? MAR_FOLLOW_PAPER : c >= 12 ? MAR_FOLLOW_MODEL : MAR_FOLLOW_SMOOTH;    /* model: 12, 13, 15, 16 */
        o.search_budget = (int)uniform(1.0, 2000.0);
        o.latency = uniform(0.0, 0.06);
        int status = 0;
        mar_follow *f = onsets ? mar_follow_create_onsets(&o, stored, stored_onset, N, &status)
                               : mar_follow_create(&o, stored, N, &status);
        CHECK(f, "create failed: %d", status);
        if (!f)
            continue;
        if (c % 2)
            mar_follow_reset(f, uniform(-100.0, (double)N + 100.0));
        double start = uniform(0.0, 1500.0), rate = uniform(0.92, 1.08);
        long before = allocations;
        uint64_t bad = 0;
        for (size_t k = 0; k < STEPS; k++) {
            double u = uniform(0.0, 1.0), live;
            if (u < 0.02)
                live = NAN;
            else if (u < 0.03)
                live = -uniform(0.0, 1.0), bad++;
            else if (u < 0.04)
                live = u < 0.035 ? INFINITY : -INFINITY, bad++;
            else if (k > 1200 && k < 1400)
                live = c % 2 ? 0.0 : 1e-3 * uniform(0.5, 1.0);     /* silence or hiss */
            else
                live = live_at(stored, N, start, rate, k) * (k > 1800 ? 10.0 : 1.0);
            /* onsets from u, not the generator: the music of later tests stays as it was */
            double onset = u > 0.98 ? NAN : 3.0 * fabs(sin(0.7 * (double)k + (double)c));  /* NaN: none came */
            if (onsets && u >= 0.04 && u < 0.05)
                onset = u < 0.045 ? -u : INFINITY, bad++;
            mar_follow_out out;
            mar_follow_step_onset(f, live, onset, &out);
            CHECK(isfinite(out.position) && out.position >= 0.0 && out.position <= (double)N,
                  "case %d step %zu: position %g", c, k, out.position);
            CHECK(isfinite(out.rate) && out.rate >= 0.0 && out.rate <= 2.0, "case %d step %zu: rate %g", c,
                  k, out.rate);
            CHECK(out.confidence >= 0.0 && out.confidence <= 1.0, "confidence %g", out.confidence);
            CHECK(out.state >= MAR_FOLLOW_SEARCHING && out.state <= MAR_FOLLOW_PAUSED, "state %d", out.state);
            if (o.mode == MAR_FOLLOW_PAPER && out.state != MAR_FOLLOW_SEARCHING)
                CHECK(out.rate == 0.0 || out.rate == 1.0 || out.rate == 2.0, "paper rate %g", out.rate);
            if (!isfinite(live) || live < 0.0)
                CHECK(out.flags & MAR_FOLLOW_F_NO_FRAME, "missing frame not flagged");
            int good_live = isfinite(live) && live >= 0.0;
            int bad_onset = onsets && good_live && !isnan(onset) && !(isfinite(onset) && onset >= 0.0);
            if ((isfinite(live) && live < 0.0) || bad_onset)
                CHECK(out.flags & MAR_FOLLOW_F_BAD_INPUT, "negative frame or onset not flagged");
            if (good_live && !bad_onset)
                CHECK(!(out.flags & MAR_FOLLOW_F_NO_FRAME), "a good frame (onset %g) not taken", onset);
        }
        CHECK(allocations == before, "case %d: steps allocated %ld times", c, allocations - before);
        mar_follow_counters cnt;
        mar_follow_get_counters(f, &cnt);
        CHECK(cnt.steps == STEPS && cnt.bad_input == bad, "counters: steps %llu bad %llu (expected %llu)",
              (unsigned long long)cnt.steps, (unsigned long long)cnt.bad_input, (unsigned long long)bad);
        CHECK(mar_follow_stored_length(f) == N, "stored length");
        mar_follow_destroy(f);
    }
}

/* A known speed: locks and follows to a fraction of a tick. */
static void test_follows(void)
{
    enum { N = 6000, STEPS = 3000 };
    static double stored[N];
    music(stored, N, 3.0);
    mar_follow_options o;
    mar_follow_default_options(&o);
    int status = 0;
    mar_follow *f = mar_follow_create(&o, stored, N, &status);
    CHECK(f, "create failed: %d", status);
    if (!f)
        return;
    const double start = 1234.0, rate = 1.03;
    double worst = 0.0;
    int locked = 0;
    for (size_t k = 0; k < STEPS; k++) {
        mar_follow_out out;
        mar_follow_step(f, live_at(stored, N, start, rate, k), &out);
        double truth = start + rate * (double)(k + 1);      /* end of frame k */
        if (out.state == MAR_FOLLOW_LOCKED && !locked)
            locked = (int)k + 1;
        if (k > 1000)
            worst = fmax(worst, fabs(out.position - truth));
    }
    CHECK(locked > 0 && locked < 500, "locked at step %d", locked);
    CHECK(worst < 1.0, "position error up to %g ticks", worst);
    mar_follow_destroy(f);
}

static double gauss(void)
{
    double u = uniform(1e-12, 1.0), v = uniform(0.0, 1.0);
    return sqrt(-2.0 * log(u)) * cos(6.283185307179586 * v);
}

/* mar_corr_lags against the joint correlation computed directly (two
 * passes, each band's means removed, one correlation over every band and
 * frame; with one band Pearson's formula), on random windows, lags and
 * band counts; a copy of the stored music, scaled and with a shift per
 * band (a volume knob, a colouring), correlates 1 at its own lag. */
static void test_corr_lags(int cases)
{
    enum { CAP = 400, MAXL = 12, STRIDE = CAP + 2 * MAXL + 8, NB = MAR_CORR_MAX_BANDS };
    static double stored[NB * STRIDE], q1[NB * (STRIDE + 1)], q2[NB * (STRIDE + 1)], live[NB * CAP];
    double rho[2 * MAXL + 1];
    for (int c = 0; c < cases; c++) {
        size_t len = (size_t)uniform(4.0, (double)CAP);
        int lags = (int)uniform(0.0, (double)MAXL + 1.0);
        size_t nb = c % 2 ? 1 : (size_t)uniform(1.0, (double)NB + 1.0);
        size_t n = len + 2 * (size_t)lags + 8;
        const mar_corr_stored st = {stored, q1, q2, STRIDE, nb};
        for (size_t b = 0; b < nb; b++) {
            double *v = stored + b * STRIDE, *s1 = q1 + b * (STRIDE + 1), *s2 = q2 + b * (STRIDE + 1);
            for (size_t i = 0; i < n; i++)
                v[i] = uniform(-40.0, 0.0);
            s1[0] = s2[0] = 0.0;
            for (size_t i = 0; i < n; i++)
                s1[i + 1] = s1[i] + v[i], s2[i + 1] = s2[i] + v[i] * v[i];
        }
        long at = lags + (long)uniform(0.0, 8.0);
        int d0 = lags ? (int)uniform(-(double)lags, (double)lags + 1.0) : 0;
        int copy = c % 3 == 0;                      /* every third: a copy of the stored music at lag d0 */
        for (size_t b = 0; b < nb; b++) {
            double gain = uniform(0.5, 2.0), shift = uniform(-10.0, 10.0);   /* each band its own */
            for (size_t k = 0; k < len; k++)
                live[b * CAP + k] = copy ? gain * stored[b * STRIDE + (size_t)(at + d0) + k] + shift
                                         : uniform(-40.0, 0.0);
        }
        double spread = mar_corr_lags(live, CAP, len, &st, at, lags, rho);
        double lm[NB], ll = 0.0;
        for (size_t b = 0; b < nb; b++) {
            lm[b] = 0.0;
            for (size_t k = 0; k < len; k++)
                lm[b] += live[b * CAP + k];
            lm[b] /= (double)len;
            for (size_t k = 0; k < len; k++)
                ll += (live[b * CAP + k] - lm[b]) * (live[b * CAP + k] - lm[b]);
        }
        CHECK(fabs(spread - sqrt(ll / (double)(len * nb))) < 1e-9, "case %d: spread %g", c, spread);
        for (int d = -lags; d <= lags; d++) {
            double num = 0.0, wsum = 0.0;          /* per band Pearson, weighted by stored spread */
            for (size_t b = 0; b < nb; b++) {
                const double *sv = stored + b * STRIDE + at + d, *l = live + b * CAP;
                double sm = 0.0, cov = 0.0, ss = 0.0, lb = 0.0;
                for (size_t k = 0; k < len; k++)
                    sm += sv[k];
                sm /= (double)len;
                for (size_t k = 0; k < len; k++)
                    cov += (l[k] - lm[b]) * (sv[k] - sm), ss += (sv[k] - sm) * (sv[k] - sm),
                        lb += (l[k] - lm[b]) * (l[k] - lm[b]);
                num += sqrt(ss) * cov / sqrt(lb * ss);
                wsum += sqrt(ss);
            }
            double want = num / wsum;
            CHECK(fabs(rho[d + lags] - want) < 1e-9, "case %d lag %d: rho %.12f, directly %.12f",
                  c, d, rho[d + lags], want);
        }
        if (copy)
            CHECK(fabs(rho[d0 + lags] - 1.0) < 1e-9, "case %d: the copy correlates %.12f at its lag",
                  c, rho[d0 + lags]);
    }
    /* a flat window correlates 0, not NaN */
    const mar_corr_stored one = {stored, q1, q2, STRIDE, 1};
    for (size_t k = 0; k < 50; k++)
        live[k] = -20.0;
    mar_corr_lags(live, CAP, 50, &one, 5, 3, rho);
    for (int i = 0; i < 7; i++)
        CHECK(rho[i] == 0.0, "flat live window: rho[%d] = %g", i, rho[i]);
}

/* mar_corr_slope_center: a step in one band of a flat window (an onset)
 * puts the centre halfway between the frames either side of it, whatever
 * the step's size and the other bands' offsets; a straight ramp puts it at
 * the window's middle, as does a flat window; and on random windows it is
 * the slope-weighted mean computed directly (each band's own spread
 * from two passes, not the prefix sums). */
static void test_corr_slope_center(int cases)
{
    enum { CAP = 300, AT = 4, STRIDE = CAP + 2 * AT, NB = MAR_CORR_MAX_BANDS };
    static double v[NB * STRIDE], q1[NB * (STRIDE + 1)], q2[NB * (STRIDE + 1)];
    for (int c = 0; c < cases; c++) {
        size_t len = (size_t)uniform(3.0, (double)CAP);
        size_t nb = (size_t)uniform(1.0, (double)NB + 1.0);
        int kind = c % 4;                           /* 0: a step, 1: a ramp, 2: flat, 3: random */
        size_t k0 = (size_t)uniform(1.0, (double)len), band = (size_t)uniform(0.0, (double)nb);
        double size = uniform(-30.0, 30.0), slope = uniform(-2.0, 2.0);
        for (size_t b = 0; b < nb; b++) {
            double offset = uniform(-60.0, 0.0);
            for (size_t i = 0; i < STRIDE; i++) {
                long k = (long)i - AT;             /* frame index in the window */
                double x = offset;
                if (kind == 0 && b == band && k >= (long)k0)
                    x += size;
                else if (kind == 1)
                    x += slope * (double)k;
                else if (kind == 3)
                    x = uniform(-40.0, 0.0);
                v[b * STRIDE + i] = x;
            }
            double *s1 = q1 + b * (STRIDE + 1), *s2 = q2 + b * (STRIDE + 1);
            s1[0] = s2[0] = 0.0;
            for (size_t i = 0; i < STRIDE; i++)
                s1[i + 1] = s1[i] + v[b * STRIDE + i], s2[i + 1] = s2[i] + v[b * STRIDE + i] * v[b * STRIDE + i];
        }
        const mar_corr_stored st = {v, q1, q2, STRIDE, nb};
        double got = mar_corr_slope_center(&st, AT, len), want = 0.5 * (double)(len - 1);
        if (kind == 0 && fabs(size) > 1e-3)
            /* the first and the last frame have no central difference */
            want = k0 == 1 ? 1.0 : k0 == len - 1 ? (double)k0 - 1.0 : (double)k0 - 0.5;
        if (kind == 3) {
            double wsum = 0.0, ksum = 0.0;
            for (size_t b = 0; b < nb; b++) {
                const double *x = v + b * STRIDE + AT;
                double mean = 0.0, ss = 0.0;
                for (size_t k = 0; k < len; k++)
                    mean += x[k] / (double)len;
                for (size_t k = 0; k < len; k++)
                    ss += (x[k] - mean) * (x[k] - mean);
                for (size_t k = 1; k + 1 < len; k++) {
                    double g = 0.5 * (x[k + 1] - x[k - 1]);
                    wsum += g * g / sqrt(ss), ksum += g * g / sqrt(ss) * (double)k;
                }
            }
            want = ksum / wsum;
        }
        CHECK(fabs(got - want) < 1e-6 * (double)len, "case %d (kind %d, %zu frames, %zu bands): centre %.9f, want %.9f",
              c, kind, len, nb, got, want);
    }
}

/* Correlation along a line: live frames are smooth stored music played at
 * rate r from p0 (one in 20 missing), in 1 to 4 bands with an offset
 * each; resampled along a line d ticks
 * behind the true one, they correlate with the stored music at lag d
 * within 0.2 tick in 98 % of cases and 0.4 in all, above 0.8 (missing
 * frames and two linear interpolations of 8-tick waves cost the rest; a
 * parabola through three points of a peak that is not one is off by up
 * to 0.33 tick: the worst of 2000 cases with 10 seeds, 12 of them over 0.2). */
static void test_corr_along_a_line(int cases)
{
    enum { N = 4000, CAP = 1024, LAGS = 6, NB = 4 };
    static double stored[NB * N], q1[NB * (N + 1)], q2[NB * (N + 1)], ring[CAP * NB], out[NB * CAP];
    double rho[2 * LAGS + 1];
    int loose = 0;                                              /* cases 0.2 tick or more off */
    for (int c = 0; c < cases; c++) {
        size_t nb = 1 + (size_t)c % NB;                         /* bands: each its own waves */
        for (size_t b = 0; b < nb; b++) {
            double ph[3] = {uniform(0, 6.3), uniform(0, 6.3), uniform(0, 6.3)};
            double per[3] = {uniform(8, 20), uniform(20, 45), uniform(45, 120)};      /* [ticks] */
            double *v = stored + b * N, *s1 = q1 + b * (N + 1), *s2 = q2 + b * (N + 1);
            for (size_t j = 0; j < N; j++)
                v[j] = -20.0 + 6.0 * sin(6.283185307179586 * (double)j / per[0] + ph[0])
                       + 4.0 * sin(6.283185307179586 * (double)j / per[1] + ph[1])
                       + 3.0 * sin(6.283185307179586 * (double)j / per[2] + ph[2]);
            s1[0] = s2[0] = 0.0;
            for (size_t j = 0; j < N; j++)
                s1[j + 1] = s1[j] + v[j], s2[j + 1] = s2[j] + v[j] * v[j];
        }
        double r = uniform(0.9, 1.1), p0 = uniform(100.0, 1500.0);
        uint64_t t = (uint64_t)uniform(CAP, 2000.0);                               /* newest step */
        for (uint64_t k = t + 1 - CAP; k <= t; k++) {
            int missing = uniform(0.0, 1.0) < 0.05;
            for (size_t b = 0; b < nb; b++)             /* a knob and a colouring: an offset per band */
                ring[(k & (CAP - 1)) * nb + b] = missing ? NAN : live_at(stored + b * N, N, p0, r, (size_t)k)
                                                                 + 3.0 * (double)b - 7.0;
        }
        double p = p0 + r * (double)(t + 1);                  /* where the music is now [stored ticks] */
        size_t ages = (size_t)uniform(100.0, 900.0);
        double behind = uniform(-2.5, 2.5);                    /* the line's error [ticks] */
        const mar_corr_history live = {ring, CAP - 1, t, nb};
        long j0;
        double center;
        size_t m = mar_corr_resample(&live, ages, p - behind, r, LAGS, N - LAGS - 1, CAP, out, &j0, &center);
        CHECK(m > 0 && fabs((double)m - (double)ages * r) < 2.0, "case %d: %zu samples for %zu frames", c, m, ages);
        CHECK(fabs(center - 0.5 * (double)ages) < 0.05 * (double)ages + 1.0, "case %d: centre %g of %zu frames",
              c, center, ages);
        if (!m)
            continue;
        for (size_t b = 0; b < nb; b++) {                       /* each band's mean taken out */
            double mean = 0.0;
            for (size_t k = 0; k < m; k++)
                mean += out[b * CAP + k];
            CHECK(fabs(mean) < 1e-6 * (double)m, "case %d band %zu: mean %g left", c, b, mean / (double)m);
        }
        const mar_corr_stored st = {stored, q1, q2, N, nb};
        mar_corr_lags(out, CAP, m, &st, j0, LAGS, rho);
        double height, kappa;
        int edge;
        double lag = mar_corr_peak(rho, LAGS, &height, &kappa, &edge);
        CHECK(!edge && fabs(lag - behind) < 0.4 && height > 0.8,
              "case %d (%zu bands): line %.2f ticks behind, peak at %.3f (height %.3f)", c, nb, behind, lag,
              height);
        loose += fabs(lag - behind) >= 0.2;
    }
    CHECK(loose <= cases / 50, "%d of %d lags 0.2 tick or more off", loose, cases);
    /* too few frames, a standing line, or a line out of the piece: nothing */
    const mar_corr_history live = {ring, CAP - 1, 2000, 1};
    long j0;
    double center;
    CHECK(mar_corr_resample(&live, 1, 500.0, 1.0, 0, N, CAP, out, &j0, &center) == 0, "one frame resampled");
    CHECK(mar_corr_resample(&live, 100, 500.0, 0.0, 0, N, CAP, out, &j0, &center) == 0, "rate 0 resampled");
    CHECK(mar_corr_resample(&live, 100, 50.0, 1.0, 0, N, CAP, out, &j0, &center) == 0, "line out of the piece");
}

/* mar_corr_peak finds the top of a sampled parabola exactly, its height
 * and curvature; a maximum at either end is an edge. */
static void test_corr_peak(int cases)
{
    double rho[2 * 12 + 1];
    for (int c = 0; c < cases; c++) {
        int lags = (int)uniform(1.0, 13.0);
        double top = uniform((double)(-lags) + 0.6, (double)lags - 0.6);   /* inside, off the ends */
        double h = uniform(0.2, 1.0), k = uniform(0.01, 0.5);
        for (int i = 0; i <= 2 * lags; i++) {
            double x = (double)(i - lags) - top;
            rho[i] = h - 0.5 * k * x * x;
        }
        double height, kappa;
        int edge;
        double lag = mar_corr_peak(rho, lags, &height, &kappa, &edge);
        CHECK(!edge && fabs(lag - top) < 1e-9 && fabs(height - h) < 1e-9 && fabs(kappa - k) < 1e-9,
              "case %d: peak at %g (want %g), height %g (%g), kappa %g (%g), edge %d",
              c, lag, top, height, h, kappa, k, edge);
        for (int i = 0; i <= 2 * lags; i++)
            rho[i] = (double)i;                     /* rising to the last lag: no peak */
        lag = mar_corr_peak(rho, lags, &height, &kappa, &edge);
        CHECK(edge && lag == (double)lags && kappa == 0.0, "case %d: edge not seen", c);
    }
}

/* mar_kf against the matrix formulas written out, and the filter honest
 * about its own error: over many runs of its own model, the normalised
 * estimation error squared averages 2 (two states). */
static void test_kf(int cases)
{
    for (int c = 0; c < cases; c++) {
        mar_kf kf = {.p = uniform(0.0, 1000.0), .r = uniform(0.9, 1.1)};
        mar_kf_init(&kf, uniform(0.01, 10.0), uniform(1e-8, 1e-3));
        double q_r = uniform(0.0, 1e-6), cc = uniform(0.0, 200.0), d = uniform(-3.0, 3.0), R = uniform(0.01, 4.0);
        /* predict: P = F P F' + Q, F = [1 1; 0 1] */
        double P[2][2] = {{kf.P00, kf.P01}, {kf.P01, kf.P11}}, x0 = kf.p + kf.r, x1 = kf.r;
        double FP[2][2] = {{P[0][0] + P[1][0], P[0][1] + P[1][1]}, {P[1][0], P[1][1]}};
        double Pp[2][2] = {{FP[0][0] + FP[0][1] + MAR_KF_Q_P, FP[0][1]}, {FP[1][0] + FP[1][1], FP[1][1] + q_r}};
        mar_kf_predict(&kf, q_r);
        CHECK(fabs(kf.P00 - Pp[0][0]) < 1e-9 * (1 + Pp[0][0]) && fabs(kf.P01 - Pp[0][1]) < 1e-9 * (1 + fabs(Pp[0][1]))
              && fabs(kf.P11 - Pp[1][1]) < 1e-12 && kf.p == x0 && kf.r == x1, "case %d: predict", c);
        /* update: K = P H' / (H P H' + R), x += K d, P = (I - K H) P, H = [1, -cc] */
        double PH[2] = {Pp[0][0] - cc * Pp[0][1], Pp[1][0] - cc * Pp[1][1]};
        double S = PH[0] - cc * PH[1];
        CHECK(fabs(mar_kf_lag_var(&kf, cc) - S) < 1e-9 * (1 + fabs(S)), "case %d: lag variance", c);
        S += R;
        double K[2] = {PH[0] / S, PH[1] / S};
        double want_p = x0 + K[0] * d, want_r = x1 + K[1] * d;
        double Pu00 = Pp[0][0] - K[0] * PH[0], Pu01 = Pp[0][1] - K[0] * PH[1], Pu11 = Pp[1][1] - K[1] * PH[1];
        mar_kf_update(&kf, cc, d, R);
        CHECK(fabs(kf.p - want_p) < 1e-9 * (1 + fabs(want_p)) && fabs(kf.r - want_r) < 1e-12
              && fabs(kf.P00 - Pu00) < 1e-9 * (1 + Pu00) && fabs(kf.P01 - Pu01) < 1e-9 * (1 + fabs(Pu01))
              && fabs(kf.P11 - Pu11) < 1e-12, "case %d: update", c);
        CHECK(kf.P00 > 0.0 && kf.P11 > 0.0 && kf.P00 * kf.P11 - kf.P01 * kf.P01 > 0.0,
              "case %d: the covariance is not positive definite", c);
    }
    /* NEES: the truth moves by the filter's own model; a measurement every
     * other tick over a window centred c ticks back */
    double nees = 0.0;
    long count = 0;
    const double q_r = 1e-7, R = 0.25, cc = 40.0;
    for (int run = 0; run < 200; run++) {
        double tp = 0.0, tr = uniform(0.95, 1.05);
        mar_kf kf = {.p = tp + 2.0 * gauss(), .r = 1.0 + 0.03 * gauss()};
        mar_kf_init(&kf, 4.0, 9e-4);
        for (int k = 1; k <= 400; k++) {
            tp += tr + sqrt(MAR_KF_Q_P) * gauss();
            tr += sqrt(q_r) * gauss();
            mar_kf_predict(&kf, q_r);
            if (k % 2 == 0) {
                double z = (tp - cc * tr) - (kf.p - cc * kf.r) + sqrt(R) * gauss();
                mar_kf_update(&kf, cc, z, R);
            }
            if (k > 100) {
                double ep = tp - kf.p, er = tr - kf.r, det = kf.P00 * kf.P11 - kf.P01 * kf.P01;
                nees += (kf.P11 * ep * ep - 2.0 * kf.P01 * ep * er + kf.P00 * er * er) / det;
                count++;
            }
        }
    }
    nees /= (double)count;
    CHECK(nees > 1.7 && nees < 2.3, "NEES %.3f, a consistent filter gives 2", nees);
}

/* The deck model's motion belief at the follower's defaults (20 ms frames,
 * a stop a priori once in 120 s, a start within 3 s, level spread 6 dB,
 * each frame's evidence capped at 2). */
static mar_deck_motion playing_deck(void)
{
    mar_deck_motion m;
    mar_deck_motion_init(&m, 0.0, 0.02 / 120.0, 0.02 / 3.0);
    return m;
}

/* Frames of the motion belief until P(stopped) passes 0.5 (or crosses back
 * below it, when stopped), at most n; frames at db [dB] where the music
 * expected lies at expected [dB] over a floor at floor_db [dB], each
 * wobbling by +-wobble [dB]. */
static int frames_to_turn(mar_deck_motion *m, int n, double db, double expected, double floor_db, double wobble)
{
    int was = mar_deck_stopped(m) > 0.5;
    for (int k = 1; k <= n; k++) {
        double ev = mar_deck_level_evidence(db + uniform(-wobble, wobble), expected + uniform(-wobble, wobble),
                                            floor_db, 6.0, 2.0);
        mar_deck_motion_update(m, ev);
        if ((mar_deck_stopped(m) > 0.5) != was)
            return k;
    }
    return n + 1;
}

static void test_deck_motion(int cases)
{
    for (int c = 0; c < cases; c++) {
        double floor_db = uniform(-90.0, -40.0), loud = uniform(20.0, 50.0);     /* [dB], [dB over the floor] */
        /* silence where music is expected: stopped within half a second */
        mar_deck_motion m = playing_deck();
        int k = frames_to_turn(&m, 100, floor_db, floor_db + loud, floor_db, 1.0);
        CHECK(k <= 25, "case %d: silence %.0f dB under the music: stopped after %d frames", c, loud, k);
        /* ... and the music back: playing within a few frames */
        k = frames_to_turn(&m, 100, floor_db + loud, floor_db + loud, floor_db, 1.0);
        CHECK(k <= 10, "case %d: music back: playing after %d frames", c, k);
        /* a quiet passage (the music expected as quiet as the hiss) is no stop, however long */
        m = playing_deck();
        k = frames_to_turn(&m, 1500, floor_db, floor_db - uniform(0.0, 20.0), floor_db, 1.0);
        CHECK(k > 1500, "case %d: a quiet passage read as a stop after %d frames", c, k);
        /* music as loud as expected keeps it playing */
        m = playing_deck();
        k = frames_to_turn(&m, 1500, floor_db + loud, floor_db + loud, floor_db, 3.0);
        CHECK(k > 1500, "case %d: music read as a stop after %d frames", c, k);
        /* a dropout of two frames in the music is no stop */
        m = playing_deck();
        frames_to_turn(&m, 50, floor_db + loud, floor_db + loud, floor_db, 1.0);
        k = frames_to_turn(&m, 2, floor_db, floor_db + loud, floor_db, 0.0);
        CHECK(k > 2, "case %d: a dropout of 2 frames read as a stop", c);
    }
    /* the evidence: 0 where the two motions predict the same, its sign by the nearer one, capped */
    CHECK(mar_deck_level_evidence(-60.0, -90.0, -60.0, 6.0, 2.0) > -1e-3
          && mar_deck_level_evidence(-60.0, -90.0, -60.0, 6.0, 2.0) <= 0.0, "quiet music: evidence not ~0");
    CHECK(mar_deck_level_evidence(-60.0, -30.0, -60.0, 6.0, 2.0) == 2.0, "hiss: evidence not capped at +2");
    CHECK(mar_deck_level_evidence(-30.0, -30.0, -60.0, 6.0, 2.0) == -2.0, "music: evidence not capped at -2");
    CHECK(mar_deck_level_evidence(NAN, -30.0, -60.0, 6.0, 2.0) == 0.0, "no frame: evidence not 0");
}

static void test_deck_place(int cases)
{
    for (int c = 0; c < cases; c++) {
        double n_eff = uniform(10.0, 500.0), rho = uniform(0.05, 0.95), more = uniform(0.001, 0.04);
        /* a better fit, or more of the same fit, is more likely; no fit is no evidence */
        CHECK(mar_deck_place_evidence(rho + more, n_eff) > mar_deck_place_evidence(rho, n_eff),
              "case %d: a better fit is not more likely", c);
        CHECK(mar_deck_place_evidence(rho, 2.0 * n_eff) > mar_deck_place_evidence(rho, n_eff),
              "case %d: more values of the same fit are not more likely", c);
        CHECK(mar_deck_place_evidence(-rho, n_eff) == 0.0 && mar_deck_place_evidence(NAN, n_eff) == 0.0,
              "case %d: no fit is evidence", c);
        /* the posterior: sums to 1, ordered as the weights, moved by the evidence toward the better place */
        double log_w[4], post[4], prior[4];
        for (int i = 0; i < 4; i++)
            prior[i] = log_w[i] = uniform(-8.0, 0.0);
        double other = uniform(-10.0, 0.0);
        double rest = mar_deck_posterior(log_w, 4, other, post);
        double sum = rest;
        int top = 0;
        for (int i = 0; i < 4; i++) {
            sum += post[i];
            if (log_w[i] > log_w[top])
                top = i;
        }
        CHECK(fabs(sum - 1.0) < 1e-12, "case %d: the posterior sums to %.15f", c, sum);
        for (int i = 0; i < 4; i++)
            CHECK(post[i] <= post[top] && (post[i] > rest) == (log_w[i] > other), "case %d: order", c);
        int right = (int)uniform(0.0, 3.999);
        for (int i = 0; i < 4; i++)
            log_w[i] = prior[i] + mar_deck_place_evidence(i == right ? 0.9 : 0.5, 200.0);
        double before = post[right];
        mar_deck_posterior(log_w, 4, other + mar_deck_place_evidence(0.5, 200.0), post);
        CHECK(post[right] > before && post[right] > 0.99, "case %d: the right place at %.3f after the evidence",
              c, post[right]);
    }
}

int main(void)
{
    test_bad_options();
    test_random_inputs(18);
    test_follows();
    test_corr_lags(300);
    test_corr_slope_center(400);
    test_corr_along_a_line(200);
    test_corr_peak(300);
    test_kf(300);
    test_deck_motion(200);
    test_deck_place(300);
    if (failures) {
        fprintf(stderr, "%d checks failed\n", failures);
        return 1;
    }
    printf("C follower tests passed\n");
    return 0;
}
