#include "mar_lag.h"

#include <math.h>

/* The gap [unit, >= 0] left after holding an input gap away for t [s]. */
static double gap_after(const mar_lag *m, double gap, double t)
{
    if (m->tau <= 0.0)
        return gap > m->vmax * t ? gap - m->vmax * t : 0.0;
    double near = m->vmax * m->tau;                 /* narrower gaps close unclipped [unit] */
    double clipped = gap > near ? (gap - near) / m->vmax : 0.0;     /* time at vmax [s] */
    if (t <= clipped)
        return gap - m->vmax * t;
    return (gap < near ? gap : near) * exp(-(t - clipped) / m->tau);
}

void mar_lag_hold(mar_lag *m, double input, int64_t periods)
{
    double T = m->period, gap = input - m->y;       /* [unit] */
    double s = gap < 0.0 ? -1.0 : 1.0;
    /* written as the input minus what is left, so that a drive that
     * reaches its input lands on it exactly */
    double before = periods > 1 ? input - s * gap_after(m, fabs(gap), (double)(periods - 1) * T) : m->y;
    if (periods > 1)                                /* the last two ticks of this hold */
        m->gap[0] = s * gap_after(m, fabs(gap), (double)(periods - 2) * T);
    else
        m->gap[0] = m->gap[1];
    m->gap[1] = input - before;
    m->y = input - s * gap_after(m, fabs(gap), (double)periods * T);
    m->v = (m->y - before) / T;
}

double mar_lag_input(const mar_lag *m, double move)
{
    double T = m->period, d = fabs(move), s = move < 0.0 ? -1.0 : 1.0;
    double near = m->vmax * m->tau;                 /* [unit] */
    if (d >= m->vmax * T)
        return m->y + s * (near + m->vmax * T);
    if (m->tau <= 0.0)
        return m->y + move;
    double alpha = -expm1(-T / m->tau);             /* share of an unclipped gap closed in a tick */
    if (d <= near * alpha)
        return m->y + move / alpha;
    /* gap = near + w: w / vmax at top speed, then the rest of the tick
     * exponentially; moved(w) = w + near * (1 - exp(-(T - w / vmax) / tau))
     * rises and is concave, so Newton from w = 0 climbs to the root */
    double w = 0.0;
    for (int i = 0; i < 30; i++) {
        double e = exp(-(T - w / m->vmax) / m->tau);
        double f = w + near * (1.0 - e) - d, slope = 1.0 - e;
        if (f >= 0.0 || !(slope > 0.0))
            break;
        double step = -f / slope;
        w += step;
        if (step <= 1e-12 * (near + w))
            break;
    }
    return m->y + s * (near + w);
}

/* The motion of a tick started gap [unit] away from its input: its velocity
 * is sign(gap) * vmax * min(1, exp(-(t - c) / tau)) at t [s] into the tick,
 * the shape V(t - c) shifted by c [s] (at top speed until c, then the lag's
 * decay; a gap narrower than vmax * tau starts below top speed: c < 0). */
typedef struct {
    double sign;        /* direction of the motion, 0 at rest */
    double gap;         /* |gap| [unit] */
    double c;           /* shift [s]: when the drive leaves top speed */
} tick_shape;

static tick_shape shape_of(const mar_lag *m, double gap)
{
    double g = fabs(gap), near = m->vmax * m->tau;  /* [unit] */
    tick_shape s = { gap < 0.0 ? -1.0 : gap > 0.0 ? 1.0 : 0.0, g, 0.0 };
    if (g >= near)
        s.c = (g - near) / m->vmax;
    else
        s.c = m->tau * log(g / near);               /* -inf at rest: moves nothing */
    return s;
}

/* Position [unit] the shape reaches from its start, t [s] into the tick. */
static double shape_disp(const mar_lag *m, tick_shape s, double t)
{
    if (s.sign == 0.0)
        return 0.0;
    double near = m->vmax * m->tau;                 /* [unit] */
    if (t <= s.c)                                   /* still at top speed */
        return s.sign * m->vmax * t;
    if (s.c >= 0.0)
        return s.sign * (m->vmax * s.c - near * expm1(-(t - s.c) / m->tau));
    return -s.sign * s.gap * expm1(-t / m->tau);
}

/* Its velocity [unit/s] t [s] into the tick (just after t at a kink). */
static double shape_vel(const mar_lag *m, tick_shape s, double t)
{
    if (s.sign == 0.0 || (m->tau <= 0.0 && t >= s.c))
        return 0.0;
    return t < s.c ? s.sign * m->vmax : s.sign * m->vmax * exp(-(t - s.c) / m->tau);
}

/* The drive's acceleration measured at the scale of a tick, t [s] into the
 * next tick: its move over the tick ending then less the move over the
 * tick before, / T^2 [unit/s^2], for the shapes of the two ticks before
 * (s[0], s[1]) and of the next (s[2]). */
static double measure_at(const mar_lag *m, const tick_shape s[3], double t)
{
    double T = m->period;
    double moved = shape_disp(m, s[1], T) - shape_disp(m, s[0], T);
    moved += shape_disp(m, s[2], t) - 2.0 * shape_disp(m, s[1], t) + shape_disp(m, s[0], t);
    return moved / (T * T);
}

/* The lowest and highest of that measure over the next tick (0 < t <= T).
 * Between the shapes' kinks each velocity is constant or decays as
 * exp(-t / tau), so the measure's slope is A + B exp(-t / tau): it is
 * extreme at the tick's end, at a kink or where that slope is 0. */
static void measure_range(const mar_lag *m, const tick_shape s[3], double range[2])
{
    double T = m->period, cut[5] = { 0.0, T, T, T, T };  /* [s] */
    int n = 1;
    for (int i = 0; i < 3; i++) {                   /* kinks inside the tick, sorted */
        if (s[i].sign == 0.0 || !(s[i].c > 0.0 && s[i].c < T))
            continue;
        int k = n++;
        for (; k > 1 && cut[k - 1] > s[i].c; k--)
            cut[k] = cut[k - 1];
        cut[k] = s[i].c;
    }
    cut[n] = T;
    range[0] = range[1] = measure_at(m, s, T);
    static const double weight[3] = { 1.0, -2.0, 1.0 };
    for (int k = 0; k < n; k++) {
        double a = cut[k], b = cut[k + 1];
        if (k > 0) {
            double x = measure_at(m, s, a);
            range[0] = x < range[0] ? x : range[0];
            range[1] = x > range[1] ? x : range[1];
        }
        if (m->tau <= 0.0 || b <= a)
            continue;
        double flat = 0.0, slope_a = 0.0;           /* [unit/s] */
        for (int i = 0; i < 3; i++) {
            double v = weight[i] * shape_vel(m, s[i], a);
            slope_a += v;
            if (s[i].c >= b)                        /* at top speed all through (a, b) */
                flat += v;
        }
        double decay = slope_a - flat;              /* B exp(-a / tau) */
        if (flat != 0.0 && -decay / flat > 1.0) {   /* the slope's zero lies after a */
            double t = a + m->tau * log(-decay / flat);
            if (t < b) {
                double x = measure_at(m, s, t);
                range[0] = x < range[0] ? x : range[0];
                range[1] = x > range[1] ? x : range[1];
            }
        }
    }
}

/* The lowest (side 0) or highest (side 1) input [unit] that, held for the
 * next tick, keeps that measure within +-amax [unit/s^2] at every instant
 * of it. Each instant's measure rises with the input (a drive given more
 * never lags one given less), so the bound is found by bisection. */
static double measure_bound(const mar_lag *m, double amax, int side)
{
    double far = m->vmax * (m->tau + m->period);    /* wider gaps all move at top speed [unit] */
    tick_shape s[3] = { shape_of(m, m->gap[0]), shape_of(m, m->gap[1]), { 0.0, 0.0, 0.0 } };
    double range[2], a = -far, b = far;             /* side 0: the lowest gap allowed is in (a, b] */
    for (int i = 0; i < 48 && b - a > 1e-10 * far; i++) {
        double mid = 0.5 * (a + b);
        s[2] = shape_of(m, mid);
        measure_range(m, s, range);
        int ok = side == 0 ? range[0] >= -amax : range[1] <= amax;
        if (ok == (side == 0))
            b = mid;
        else
            a = mid;
    }
    return m->y + (side == 0 ? b : a);
}

/* The inputs [unit], window[0] <= window[1], that keep that measure within
 * +-amax at every instant of the next tick; side 0 or 1 alone (the other
 * end left at the tick's bound below), or both (side -1). Returns 0; or 1
 * when none does (the motion before asked too much), and window is then
 * the inputs that keep it so at the tick's end alone: the drive's velocity
 * over the tick changes by at most amax * T. */
static int accel_window(const mar_lag *m, double amax, int side, double window[2])
{
    double T = m->period, lo = -INFINITY, hi = INFINITY;
    window[0] = mar_lag_input(m, (m->v - amax * T) * T);
    window[1] = mar_lag_input(m, (m->v + amax * T) * T);
    if (m->tau <= 0.0)      /* a drive taken to follow its command: between the ticks it interpolates them */
        return 0;
    if (side != 1)
        lo = measure_bound(m, amax, 0);
    if (side != 0)
        hi = measure_bound(m, amax, 1);
    lo = lo > window[0] ? lo : window[0];
    hi = hi < window[1] ? hi : window[1];
    if (lo > hi)
        return 1;
    window[0] = lo;
    window[1] = hi;
    return 0;
}

/* How far [unit] the drive moves in the next tick holding input. */
static double tick_move(const mar_lag *m, double input)
{
    return shape_disp(m, shape_of(m, input - m->y), m->period);
}

/* Whether input, held for the next tick, keeps that tick's measure within
 * +-amax (a relative 1e-9 for rounding). */
static int input_fits(const mar_lag *m, double amax, double input)
{
    if (m->tau <= 0.0)      /* as accel_window: the velocity over the tick changes by at most amax * T */
        return fabs(tick_move(m, input) - m->v * m->period) <= amax * m->period * m->period * (1.0 + 1e-9);
    tick_shape s[3] = { shape_of(m, m->gap[0]), shape_of(m, m->gap[1]), shape_of(m, input - m->y) };
    double range[2];
    measure_range(m, s, range);
    return range[0] >= -amax * (1.0 + 1e-9) && range[1] <= amax * (1.0 + 1e-9);
}

#define STOP_CANDIDATES 12      /* inputs tried across the window when the profile cannot be followed */

int mar_lag_stop_input(const mar_lag *m, double amax, double goal, double after, double window[2],
                       double *input)
{
    /* 1. the profile followed this tick and the next, if the drive can */
    double want = mar_lag_input(m, goal - m->y);                     /* [unit] */
    accel_window(m, amax, -1, window);
    mar_lag next = *m;
    mar_lag_hold(&next, want, 1);
    if (want >= window[0] && want <= window[1] && input_fits(&next, amax, mar_lag_input(&next, after - next.y))) {
        *input = want;
        return 0;
    }
    /* 2. else the input in the window that, followed by the hardest braking
     *    the next tick allows, brakes most over the two ticks, but no more
     *    than the profile: at the drive's top speed its motion within a
     *    tick changes shape as it slows, and braking hard in one tick can
     *    leave the next none (docs/architecture.md, Stops) */
    double s = m->v > 0.0 ? 1.0 : m->v < 0.0 ? -1.0 : goal >= m->y ? 1.0 : -1.0;
    double planned = s * (after - m->y);                             /* [unit] */
    double best = window[0] > want ? window[0] : window[1] < want ? window[1] : want;
    double best_moved = INFINITY, best_off = INFINITY;
    for (int i = 0; i <= STOP_CANDIDATES; i++) {
        double u = window[0] + (window[1] - window[0]) * i / STOP_CANDIDATES;
        next = *m;
        mar_lag_hold(&next, u, 1);
        double w2[2];
        accel_window(&next, amax, s > 0.0 ? 0 : 1, w2);
        double moved = s * (tick_move(m, u) + tick_move(&next, s > 0.0 ? w2[0] : w2[1]));
        moved = moved < planned ? planned : moved;
        double off = fabs(u - want);
        if (moved < best_moved || (moved == best_moved && off < best_off)) {
            best = u;
            best_moved = moved;
            best_off = off;
        }
    }
    *input = best;
    return 1;
}
