#include "mar_shape.h"

#include <errno.h>
#include <math.h>

/* Relative slack [1] of the feasibility test: a distance that exceeds the
 * reach only by rounding (e.g. a target reduced to exactly the reach) fits;
 * the profile's acceleration and speed are then clamped to the limits. */
#define FIT_SLACK 1e-12

static int finite_positive(double v)
{
    return isfinite(v) && v > 0.0;
}

static int fits(double distance, double reach)
{
    return distance <= reach + FIT_SLACK * reach;
}

double mar_shape_reach(double T, double vmax, double amax)
{
    if (!finite_positive(vmax) || !finite_positive(amax) || isnan(T))
        return NAN;
    if (T <= 0.0)
        return 0.0;
    if (T >= 2.0 * vmax / amax)
        return vmax * T - vmax * vmax / amax;   /* trapezoid at vmax, amax [unit] */
    return 0.25 * amax * T * T;                 /* triangle at amax [unit] */
}

double mar_shape_min_time(double distance, double vmax, double amax)
{
    if (!finite_positive(vmax) || !finite_positive(amax) || isnan(distance))
        return NAN;
    double d = fabs(distance);                  /* [unit] */
    if (d <= vmax * vmax / amax)
        return 2.0 * sqrt(d / amax);            /* triangle at amax [s] */
    return d / vmax + vmax / amax;              /* trapezoid at vmax, amax [s] */
}

int mar_shape_plan(double x0, double x1, double t0, double T,
                   double vmax, double amax, mar_shape_profile *p)
{
    if (p == NULL || !isfinite(x0) || !isfinite(x1) || !isfinite(t0) ||
        !finite_positive(T) || !finite_positive(vmax) || !finite_positive(amax))
        return -EINVAL;
    double d = fabs(x1 - x0);                   /* distance [unit] */
    if (!isfinite(d))
        return -EINVAL;
    if (!fits(d, mar_shape_reach(T, vmax, amax)))
        return MAR_SHAPE_INFEASIBLE;
    double accel, peak, ramp;                   /* [unit/s^2], [unit/s], [s] */
    if (d == 0.0) {
        accel = 0.0;
        peak = 0.0;
        ramp = 0.5 * T;
    } else if (2.0 * d <= vmax * T) {
        /* triangle: the least peak acceleration of any rest-to-rest move */
        ramp = 0.5 * T;
        accel = 4.0 * d / (T * T);
        peak = 2.0 * d / T;
    } else {
        /* the triangle would be too fast: cruise at vmax; d = vmax*(T - ramp) */
        ramp = T - d / vmax;
        peak = vmax;
        accel = vmax / ramp;
    }
    if (accel > amax)       /* only by rounding: fits() allowed FIT_SLACK */
        accel = amax;
    if (peak > vmax)
        peak = vmax;
    p->t0 = t0;
    p->duration = T;
    p->x0 = x0;
    p->x1 = x1;
    p->accel = accel;
    p->peak_speed = peak;
    p->ramp = ramp;
    p->smooth = 0.0;
    p->accel_end = accel;
    p->ramp_end = ramp;
    p->turn = p->turn_end = 0.0;
    p->open = 0;
    p->reserved = 0;
    return 0;
}

/* Candidate smoothing widths per move: fractions i/SMOOTH_STEPS of its
 * duration; the best reach among them is within a few percent of the best
 * over all widths. */
#define SMOOTH_STEPS 32

void mar_shape_lag_limits(double w, double lag, double vmax, double amax,
                          double *speed, double *accel)
{
    double a = amax, v = vmax;
    if (lag > 0.0) {
        a = w > 0.0 ? amax * w / (w + lag) : 0.0;
        if (a > 0.5 * vmax / lag)
            a = 0.5 * vmax / lag;
        /* the feed-forward's speed peaks inside a window over a corner of the
         * ramp: x' + lag*x'' <= v + a*lag^2/(2w) (lag <= w), v + a*(lag - w/2) */
        v = vmax - a * (lag <= w ? lag * lag / (2.0 * w) : lag - 0.5 * w);
    }
    *speed = v;
    *accel = a;
}

/* Largest |D| [unit] of a core of Tc [s] at speed v [unit/s] and
 * acceleration a [unit/s^2] that cruises at least w [s] between its ramps
 * (so that the moving average over w never joins two of its corners). */
static double core_reach(double Tc, double w, double v, double a)
{
    if (!(Tc > w) || !(a > 0.0))
        return 0.0;
    double r = 0.5 * (Tc - w);                  /* ramps with a cruise of just w [s] */
    if (a * r <= v)
        return a * r * (r + w);
    return v * (Tc - v / a);                    /* cruising at v, longer than w */
}

/* The least-acceleration core for |D| = d [unit] over Tc [s] that cruises
 * at least w [s]; 0, or MAR_SHAPE_INFEASIBLE beyond core_reach. */
static int plan_core(double d, double Tc, double w, double v, double a, mar_shape_profile *p)
{
    if (!fits(d, core_reach(Tc, w, v, a)))
        return MAR_SHAPE_INFEASIBLE;
    double r = 0.5 * (Tc - w), peak = d / (r + w), accel;       /* [s], [unit/s] */
    if (peak > v) {                             /* cruise at v, longer than w */
        peak = v;
        r = Tc - d / v;
    }
    accel = r > 0.0 ? peak / r : 0.0;
    p->accel = accel > a ? a : accel;           /* only by rounding: fits() allowed FIT_SLACK */
    p->peak_speed = peak;
    p->ramp = r;
    return 0;
}

double mar_shape_reach_lag(double T, double vmax, double amax, double lag, double *smooth)
{
    double best = mar_shape_reach(T, vmax, amax), best_w = 0.0;
    if (!isfinite(best) || !(lag > 0.0)) {
        if (smooth != NULL)
            *smooth = 0.0;
        return isnan(lag) || lag < 0.0 ? NAN : best;
    }
    best = 0.0;
    for (int i = 1; i < SMOOTH_STEPS; ++i) {
        double w = T * (double)i / SMOOTH_STEPS, v, a;     /* [s], [unit/s], [unit/s^2] */
        mar_shape_lag_limits(w, lag, vmax, amax, &v, &a);
        double r = core_reach(T - w, w, v, a);
        if (r > best) {
            best = r;
            best_w = w;
        }
    }
    if (smooth != NULL)
        *smooth = best_w;
    return best;
}

int mar_shape_plan_lag(double x0, double x1, double t0, double T,
                       double vmax, double amax, double lag, mar_shape_profile *p)
{
    if (!(lag > 0.0))
        return lag == 0.0 ? mar_shape_plan(x0, x1, t0, T, vmax, amax, p) : -EINVAL;
    if (p == NULL || !isfinite(x0) || !isfinite(x1) || !isfinite(t0) || !finite_positive(T) ||
        !finite_positive(vmax) || !finite_positive(amax) || !isfinite(lag))
        return -EINVAL;
    double d = fabs(x1 - x0);                   /* [unit] */
    double w, v, a;                             /* [s], [unit/s], [unit/s^2] */
    if (!fits(d, mar_shape_reach_lag(T, vmax, amax, lag, &w)))
        return MAR_SHAPE_INFEASIBLE;
    /* the narrowest window that fits: the move ends at rest with no
     * acceleration, and a wide window flattens the climax more than needed */
    for (int i = 1; i < SMOOTH_STEPS; ++i) {
        double wi = T * (double)i / SMOOTH_STEPS;
        mar_shape_lag_limits(wi, lag, vmax, amax, &v, &a);
        if (fits(d, core_reach(T - wi, wi, v, a))) {
            w = wi;
            break;
        }
    }
    mar_shape_lag_limits(w, lag, vmax, amax, &v, &a);
    if (d == 0.0) {
        p->accel = p->peak_speed = 0.0;
        p->ramp = 0.5 * (T - w);
    } else if (plan_core(d, T - w, w, v, a, p) != 0) {
        return MAR_SHAPE_INFEASIBLE;            /* rounding at the edge of the reach */
    }
    p->t0 = t0;
    p->duration = T;
    p->x0 = x0;
    p->x1 = x1;
    p->smooth = w;
    p->accel_end = p->accel;
    p->ramp_end = p->ramp;
    p->turn = p->turn_end = 0.0;
    p->open = 0;
    p->reserved = 0;
    return 0;
}

/* Closed-end accelerations mar_shape_plan_open tries: the open end's ramp's,
 * the limit and 10 halvings of it. */
#define CLOSED_TRIES 12
/* Ramp accelerations it tries at an open end: from the turn's up to the
 * limit, geometrically. */
#define RAMP_TRIES 8

/* One end of a core: a turn of acceleration g [unit/s^2] over r [s] (r = 0
 * at a closed end), then a ramp of acceleration A from speed u = g*r. */
typedef struct {
    double g, r, A;
} core_end;

/* The cruise speed [unit/s] of a core of Tc [s] over dc [unit] with ends s
 * and e, or INFINITY when none: each end at V spends r + (V - u)/A [s] and
 * covers u*r/2 + (V^2 - u^2)/(2A), so dc = V*Tc - sum((V - u)^2/(2A) + V*r - u*r/2). */
static double cruise_speed(double Tc, double dc, core_end s, core_end e)
{
    double us = s.g * s.r, ue = e.g * e.r;                  /* [unit/s] */
    double h = 0.5 / s.A + 0.5 / e.A;                       /* [s^2/unit] */
    double b = Tc - (s.r - us / s.A) - (e.r - ue / e.A);    /* [s] */
    double c = dc + 0.5 * us * (us / s.A - s.r) + 0.5 * ue * (ue / e.A - e.r);  /* [unit] */
    double disc = b * b - 4.0 * h * c;                      /* [s^2] */
    if (!(b > 0.0) || !(c > 0.0) || disc < 0.0)
        return INFINITY;
    return 2.0 * c / (b + sqrt(disc));
}

/* Acceleration [unit/s^2] of try k of n from g up to a, geometrically. */
static double ramp_try(double g, double a, int k, int n)
{
    return n > 1 && g < a ? g * pow(a / g, (double)k / (n - 1)) : g;
}

int mar_shape_plan_open(double x0, double x1, double t0, double T, double vmax, double amax,
                        double lag, double w, int open, double g_start, double g_end,
                        mar_shape_profile *p)
{
    if (p == NULL || !isfinite(x0) || !isfinite(x1) || !isfinite(t0) || !finite_positive(T) ||
        !finite_positive(vmax) || !finite_positive(amax) || !isfinite(lag) || lag < 0.0 ||
        !isfinite(w) || w < 0.0 || w >= T || (open & ~(MAR_SHAPE_OPEN_START | MAR_SHAPE_OPEN_END)) ||
        ((open & MAR_SHAPE_OPEN_START) && !finite_positive(g_start)) ||
        ((open & MAR_SHAPE_OPEN_END) && !finite_positive(g_end)))
        return -EINVAL;
    int os = (open & MAR_SHAPE_OPEN_START) != 0, oe = (open & MAR_SHAPE_OPEN_END) != 0;
    double v, a;                                /* the limits [unit/s], [unit/s^2] */
    mar_shape_lag_limits(w, lag, vmax, amax, &v, &a);
    double d = fabs(x1 - x0);                   /* [unit] */
    if (d == 0.0)
        return MAR_SHAPE_INFEASIBLE;            /* no turn at a move that stands still */
    if ((os && g_start > a * (1.0 + FIT_SLACK)) || (oe && g_end > a * (1.0 + FIT_SLACK)))
        return MAR_SHAPE_INFEASIBLE;
    double Tc = T - (os ? 0.0 : 0.5 * w) - (oe ? 0.0 : 0.5 * w);     /* the core [s] */
    double dc = d + ((os ? g_start : 0.0) + (oe ? g_end : 0.0)) * w * w / 24.0;  /* [unit] */
    /* without smoothing the turn is the ramp itself */
    int ns = os ? (w > 0.0 ? RAMP_TRIES : 1) : 1, ne = oe ? (w > 0.0 ? RAMP_TRIES : 1) : 1;
    int nc = os && oe ? 1 : CLOSED_TRIES;
    for (int ks = 0; ks < ns; ++ks)
        for (int ke = 0; ke < ne; ++ke)
            for (int c = 0; c < nc; ++c) {
                double as = ramp_try(g_start, a, ks, ns), ae = ramp_try(g_end, a, ke, ne);
                /* a closed end: the open end's ramp's acceleration, the limit, then
                 * halves of it (a gentle closed end makes the cruise faster, so the
                 * open end's turn leaves below the cruise's speed) */
                double closed = c > 0 ? a * ldexp(1.0, 1 - c) : os ? as : oe ? ae : a;
                core_end s = os ? (core_end){g_start, 0.5 * w, as} : (core_end){0.0, 0.0, closed};
                core_end e = oe ? (core_end){g_end, 0.5 * w, ae} : (core_end){0.0, 0.0, closed};
                double V = cruise_speed(Tc, dc, s, e);              /* [unit/s] */
                double us = s.g * s.r, ue = e.g * e.r;
                double rs = V > us ? (V - us) / s.A : 0.0, re = V > ue ? (V - ue) / e.A : 0.0;
                double lo = 1.0 - FIT_SLACK, hi = 1.0 + FIT_SLACK;
                if (!(V <= v * hi) || !(V >= us * lo) || !(V >= ue * lo) ||
                    !(Tc - s.r - rs - e.r - re >= w * lo))
                    continue;
                p->t0 = t0;
                p->duration = T;
                p->x0 = x0;
                p->x1 = x1;
                p->accel = s.A;
                p->accel_end = e.A;
                p->peak_speed = V > v ? v : V;
                p->ramp = rs;
                p->ramp_end = re;
                p->turn = os ? g_start : 0.0;
                p->turn_end = oe ? g_end : 0.0;
                p->smooth = w;
                p->open = open;
                p->reserved = 0;
                return 0;
            }
    return MAR_SHAPE_INFEASIBLE;
}

/* The core, in the move's direction, as pieces of constant acceleration:
 * from time t [s] after the core starts, position y [unit], velocity v
 * [unit/s], acceleration a [unit/s^2], and the integral of y from the first
 * piece's start [unit*s] (for the moving average). */
typedef struct {
    double t, y, v, a, i;
} core_piece;

#define CORE_PIECES 7

/* The pieces of a core of Tc [s] over dc [unit], from -w (the earliest a
 * window reaches) on: before the core, an open start's parabola (else rest);
 * the start's turn and ramp, the cruise, the end's ramp and turn; after the
 * core, an open end's parabola (else rest), from exactly dc at rest. */
static void core_pieces(const mar_shape_profile *p, double Tc, double dc, core_piece *q)
{
    int os = (p->open & MAR_SHAPE_OPEN_START) != 0, oe = (p->open & MAR_SHAPE_OPEN_END) != 0;
    double w = p->smooth, rts = os ? 0.5 * w : 0.0, rte = oe ? 0.5 * w : 0.0;   /* [s] */
    double gs = os ? p->turn : 0.0, ge = oe ? p->turn_end : 0.0;               /* [unit/s^2] */
    double ts[CORE_PIECES] = {-w, 0.0, rts, rts + p->ramp, Tc - rte - p->ramp_end, Tc - rte, Tc};
    double as[CORE_PIECES] = {gs, gs, p->accel, 0.0, -p->accel_end, -ge, -ge};
    q[0] = (core_piece){-w, 0.5 * gs * w * w, -gs * w, gs, 0.0};
    for (int k = 1; k < CORE_PIECES; ++k) {
        const core_piece *b = &q[k - 1];
        double h = ts[k] > b->t ? ts[k] - b->t : 0.0;       /* [s] */
        q[k] = (core_piece){b->t + h, b->y + b->v * h + 0.5 * b->a * h * h, b->v + b->a * h,
                            as[k], b->i + b->y * h + 0.5 * b->v * h * h + b->a * h * h * h / 6.0};
    }
    q[CORE_PIECES - 1].y = dc;                  /* the end exact: no rounding drift */
    q[CORE_PIECES - 1].v = 0.0;
}

/* y of the core at tau [s] (its velocity, acceleration and integral out). */
static double core_at(const core_piece *q, double tau, double *v, double *a, double *i)
{
    int k = 0;
    while (k + 1 < CORE_PIECES && q[k + 1].t <= tau)
        ++k;
    double h = tau - q[k].t;                    /* [s], < 0 only before the first piece */
    if (v != NULL)
        *v = q[k].v + q[k].a * h;
    if (a != NULL)
        *a = q[k].a;
    if (i != NULL)
        *i = q[k].i + q[k].y * h + 0.5 * q[k].v * h * h + q[k].a * h * h * h / 6.0;
    return q[k].y + q[k].v * h + 0.5 * q[k].a * h * h;
}

/* Position [unit] at tau [s] after departure; velocity and acceleration out:
 * the core itself, or its moving average over p->smooth. */
static double eval_local(const mar_shape_profile *p, double tau, double *v, double *a)
{
    double w = p->smooth, s = p->x1 >= p->x0 ? 1.0 : -1.0;     /* [s], direction [1] */
    int os = (p->open & MAR_SHAPE_OPEN_START) != 0, oe = (p->open & MAR_SHAPE_OPEN_END) != 0;
    double q0 = os ? 0.0 : 0.5 * w;                 /* the core starts [s] */
    double Tc = p->duration - q0 - (oe ? 0.0 : 0.5 * w);
    double shift = w * w / 24.0;                    /* a parabola's, averaged over w [s^2] */
    double c0 = p->x0 - (os ? s * p->turn * shift : 0.0);       /* the core's start [unit] */
    double dc = fabs(p->x1 - p->x0) + ((os ? p->turn : 0.0) + (oe ? p->turn_end : 0.0)) * shift;
    double lo = p->x0 < p->x1 ? p->x0 : p->x1, hi = p->x0 < p->x1 ? p->x1 : p->x0;
    double x, vel = 0.0, ac = 0.0;
    core_piece q[CORE_PIECES];
    if (tau <= 0.0) {
        x = p->x0;
    } else if (tau >= p->duration) {
        x = p->x1;                                  /* the end is hit bit for bit */
    } else {
        core_pieces(p, Tc, dc, q);
        if (!(w > 0.0)) {
            x = c0 + s * core_at(q, tau, &vel, &ac, NULL);
        } else {
            double t = tau - q0;                    /* the window's middle, core time [s] */
            double v1, v0, i1, i0;
            double y1 = core_at(q, t + 0.5 * w, &v1, NULL, &i1);
            double y0 = core_at(q, t - 0.5 * w, &v0, NULL, &i0);
            x = c0 + s * (i1 - i0) / w;
            vel = (y1 - y0) / w;
            ac = (v1 - v0) / w;
        }
    }
    if (tau == 0.0 && os) {                         /* a turn: at rest, accelerating */
        ac = p->turn;
    } else if (tau == p->duration && oe) {
        ac = -p->turn_end;
    }
    x = x < lo ? lo : x > hi ? hi : x;              /* a monotone move: rounding never passes an end */
    if (v != NULL)
        *v = s * vel;
    if (a != NULL)
        *a = s * ac;
    return x;
}

void mar_shape_eval(const mar_shape_profile *p, double t, double *x, double *v, double *a)
{
    double pos = eval_local(p, t - p->t0, v, a);
    if (x != NULL)
        *x = pos;
}

static int push(mar_shape_extremum *out, size_t cap, size_t *count,
                size_t tick, double value, int kind)
{
    if (*count >= cap)
        return -ENOSPC;
    out[*count].tick = (int64_t)tick;
    out[*count].rest_end = (int64_t)tick;
    out[*count].value = value;
    out[*count].kind = kind;
    out[*count].reserved = 0;
    ++*count;
    return 0;
}

int mar_shape_extrema(const double *x, size_t n, double prominence, double rest_tolerance,
                      mar_shape_extremum *out, size_t cap, size_t *count)
{
    if (x == NULL || out == NULL || count == NULL || n == 0 || !finite_positive(prominence) ||
        !isfinite(rest_tolerance) || rest_tolerance < 0.0)
        return -EINVAL;
    for (size_t k = 0; k < n; ++k)
        if (!isfinite(x[k]))
            return -EINVAL;
    *count = 0;
    int r = push(out, cap, count, 0, x[0], 0);  /* the first sample anchors the start */
    if (r < 0)
        return r;
    /* trend 0: no excursion of the prominence yet; +1: rising, cand is the
     * highest tick since the last point of rest; -1: falling, the lowest */
    int trend = 0;
    size_t hi = 0, lo = 0, cand = 0;
    for (size_t k = 1; k < n; ++k) {
        double v = x[k];                        /* [unit] */
        if (trend == 0) {
            if (v > x[hi])
                hi = k;
            if (v < x[lo])
                lo = k;
            if (x[hi] - x[lo] >= prominence) {
                trend = k == hi ? 1 : -1;
                cand = k;
            }
        } else if (trend > 0) {
            if (v > x[cand]) {
                cand = k;
            } else if (x[cand] - v >= prominence) {
                if ((r = push(out, cap, count, cand, x[cand], 1)) < 0)
                    return r;
                trend = -1;
                cand = k;
            }
        } else {
            if (v < x[cand]) {
                cand = k;
            } else if (v - x[cand] >= prominence) {
                if ((r = push(out, cap, count, cand, x[cand], -1)) < 0)
                    return r;
                trend = 1;
                cand = k;
            }
        }
    }
    /* the end of the show confirms the pending candidate */
    if (trend != 0 && cand != n - 1)
        if ((r = push(out, cap, count, cand, x[cand], trend)) < 0)
            return r;
    if (out[*count - 1].tick != (int64_t)(n - 1))
        if ((r = push(out, cap, count, n - 1, x[n - 1], 0)) < 0)
            return r;
    /* rests: the run after each climax within the tolerance, before the next point */
    for (size_t i = 0; i + 1 < *count; ++i) {
        double v = out[i].value;
        size_t h = (size_t)out[i].tick, next = (size_t)out[i + 1].tick;
        if (fabs(out[i + 1].value - v) > rest_tolerance)
            while (h + 1 < next && fabs(x[h + 1] - v) <= rest_tolerance)
                ++h;
        out[i].rest_end = (int64_t)h;
    }
    return 0;
}

/* Candidate accelerations a turn is tried with, from the larger of its two
 * moves' down to the smaller, geometrically. */
#define TURN_TRIES 8
/* Windows a move at a turn is tried with: its own, then 7/8, 6/8 ... 1/8 of it. */
#define WINDOW_TRIES 8

/* Move m planned again with the ends of open turning at g_start and g_end
 * [unit/s^2] (mar_shape_plan_open), with the first of WINDOW_TRIES windows
 * that fits: a turn lasts half the window, so a slow move (a long one has a
 * wide window) may not be slow enough to turn in its own, and a narrow
 * window limits the acceleration. */
static int plan_turn(const mar_shape_options *opt, const mar_shape_profile *m, int open,
                     double g_start, double g_end, mar_shape_profile *out)
{
    int tries = m->smooth > 0.0 ? WINDOW_TRIES : 1;
    for (int k = 0; k < tries; ++k) {
        double w = m->smooth * (double)(tries - k) / tries;     /* [s] */
        if (mar_shape_plan_open(m->x0, m->x1, m->t0, m->duration, opt->max_speed, opt->max_accel,
                                opt->lag, w, open, g_start, g_end, out) == 0)
            return 0;
    }
    return MAR_SHAPE_INFEASIBLE;
}

/* Whether the figure turns without a rest where seg[i] arrives. */
static int turns_at(const mar_shape_segment *seg, size_t count, size_t i)
{
    if (i + 1 >= count || seg[i].arrive_tick != seg[i + 1].depart_tick)
        return 0;
    const mar_shape_profile *a = &seg[i].profile, *b = &seg[i + 1].profile;
    return (a->x1 - a->x0) * (b->x1 - b->x0) < 0.0;
}

/* The accelerations [unit/s^2] a turn from move a into move b tries: from
 * the larger of a's last ramp's and b's first down to the smaller, within
 * both windows' limits. 0 when there is nothing to try. */
static int turn_range(const mar_shape_options *opt, const mar_shape_profile *a,
                      const mar_shape_profile *b, double *hi, double *lo)
{
    double va, aa, vb, ab;                      /* each window's limits */
    mar_shape_lag_limits(a->smooth, opt->lag, opt->max_speed, opt->max_accel, &va, &aa);
    mar_shape_lag_limits(b->smooth, opt->lag, opt->max_speed, opt->max_accel, &vb, &ab);
    double cap = aa < ab ? aa : ab;
    *hi = a->accel_end > b->accel ? a->accel_end : b->accel;
    *lo = a->accel_end > b->accel ? b->accel : a->accel_end;
    *hi = *hi < cap ? *hi : cap;
    *lo = *lo < *hi ? *lo : *hi;
    return *lo > 0.0;
}

/* The turn where seg[i - 1] arrives and seg[i] leaves: the largest of
 * TURN_TRIES accelerations (turn_range) with which both moves fit
 * (plan_turn), the move before keeping its start's turn as planned, the one
 * after planned to rest at its end for now. With look_ahead, only an
 * acceleration with which the one after could also turn at its end, with
 * the least the turn there tries. Returns 1 when the moves were planned so. */
static int share_turn(const mar_shape_options *opt, mar_shape_segment *seg, size_t i,
                      int look_ahead)
{
    mar_shape_profile *a = &seg[i - 1].profile, *b = &seg[i].profile;
    double hi, lo;                              /* [unit/s^2] */
    if (!turn_range(opt, a, b, &hi, &lo))
        return 0;
    for (int c = 0; c < TURN_TRIES; ++c) {
        double shared = hi * pow(lo / hi, (double)c / (TURN_TRIES - 1));     /* [unit/s^2] */
        double next_hi, next_lo;
        mar_shape_profile pa, pb, pn;
        if (plan_turn(opt, a, (a->open & MAR_SHAPE_OPEN_START) | MAR_SHAPE_OPEN_END, a->turn,
                      shared, &pa) != 0 ||
            plan_turn(opt, b, MAR_SHAPE_OPEN_START, shared, 0.0, &pb) != 0)
            continue;
        if (look_ahead && (!turn_range(opt, &pb, &seg[i + 1].profile, &next_hi, &next_lo) ||
                           plan_turn(opt, &pb, MAR_SHAPE_OPEN_START | MAR_SHAPE_OPEN_END, shared,
                                     next_lo, &pn) != 0))
            continue;
        *a = pa;
        *b = pb;
        return 1;
    }
    return 0;
}

/* Where the figure turns at a climax without a rest (the move before it
 * arrives when the next leaves, in the other direction), the two moves
 * share an acceleration there instead of each coming to rest with none:
 * the climax is the vertex of a parabola. From the first turn to the last
 * (share_turn): where the move after turns again at its end, first looking
 * ahead (a steep turn at a slow move's start can leave it too slow to turn
 * at its end), then not. Where none fits, both keep their ends at rest. */
static void open_turns(const mar_shape_options *opt, mar_shape_segment *seg, size_t count)
{
    for (size_t i = 1; i < count; ++i)
        if (turns_at(seg, count, i - 1) && !(turns_at(seg, count, i) && share_turn(opt, seg, i, 1)))
            share_turn(opt, seg, i, 0);
}

int mar_shape_axis(const mar_shape_options *opt, const double *x, size_t n,
                   mar_shape_extremum *ext, size_t ext_cap, size_t *n_ext,
                   mar_shape_segment *seg, size_t seg_cap, size_t *n_seg,
                   double *out)
{
    if (opt == NULL || x == NULL || ext == NULL || n_ext == NULL || n_seg == NULL ||
        out == NULL || n == 0 || (seg == NULL && seg_cap > 0))
        return -EINVAL;
    double T = opt->period, vmax = opt->max_speed, amax = opt->max_accel, lag = opt->lag;
    if (!finite_positive(T) || !finite_positive(vmax) || !finite_positive(amax) ||
        !isfinite(opt->pos_min) || !isfinite(opt->pos_max) || !(opt->pos_min <= opt->pos_max) ||
        !isfinite(lag) || lag < 0.0 || !isfinite(opt->pos_margin) || opt->pos_margin < 0.0 ||
        opt->first_depart < 0 ||
        (opt->policy != MAR_SHAPE_REDUCE && opt->policy != MAR_SHAPE_BORROW &&
         opt->policy != MAR_SHAPE_REJECT))
        return -EINVAL;
    *n_seg = 0;
    int r = mar_shape_extrema(x, n, opt->prominence, opt->rest_tolerance, ext, ext_cap, n_ext);
    if (r < 0)
        return r;
    for (size_t i = 0; i < *n_ext; ++i)
        if (ext[i].value < opt->pos_min || ext[i].value > opt->pos_max)
            return -ERANGE;
    size_t count = *n_ext - 1;
    if (seg_cap < count)
        return -ENOSPC;
    /* where a move may end: the limits less the margin (their middle if that is empty) */
    double lo = opt->pos_min + opt->pos_margin, hi = opt->pos_max - opt->pos_margin;
    if (lo > hi)
        lo = hi = 0.5 * (opt->pos_min + opt->pos_max);

    int infeasible = 0;
    double start = ext[0].value;                /* planned position at the rest [unit] */
    out[0] = start;
    for (size_t i = 0; i < count; ++i) {
        const mar_shape_extremum *a = &ext[i], *b = &ext[i + 1];
        mar_shape_segment *s = &seg[i];
        int64_t earliest = a->tick;             /* the earliest departure [tick] */
        if (i == 0 && opt->first_depart > earliest)
            earliest = opt->first_depart < b->tick ? opt->first_depart : b->tick - 1;
        int64_t depart = a->rest_end > earliest ? a->rest_end : earliest;  /* nominal [tick] */
        double want = b->value < lo ? lo : b->value > hi ? hi : b->value;  /* [unit] */
        double D = want - start;                /* [unit] */
        double reach = mar_shape_reach_lag((double)(b->tick - depart) * T, vmax, amax, lag, NULL);
        double end = want;
        int action = want != b->value ? MAR_SHAPE_ACT_REDUCED : 0;
        s->shortfall = fabs(b->value - want);
        if (!fits(fabs(D), reach)) {
            s->shortfall += fabs(D) - reach;
            if (opt->policy == MAR_SHAPE_BORROW) {
                /* the latest departure, not before the climax, that fits */
                double need = mar_shape_min_time(D, vmax, amax);     /* [s], a lower bound */
                double ticks = ceil(need / T);
                int64_t d = ticks < (double)(b->tick - earliest) ? b->tick - (int64_t)ticks : earliest;
                if (d > depart)
                    d = depart;
                while (d > earliest &&
                       !fits(fabs(D), mar_shape_reach_lag((double)(b->tick - d) * T, vmax, amax,
                                                          lag, NULL)))
                    --d;
                if (d < depart)
                    action |= MAR_SHAPE_ACT_BORROWED;
                depart = d;
                reach = mar_shape_reach_lag((double)(b->tick - depart) * T, vmax, amax, lag, NULL);
            }
            if (!fits(fabs(D), reach)) {
                end = start + (D > 0.0 ? reach : -reach);
                while (fabs(end - start) > reach)   /* rounding, far from 0 with a small reach */
                    end = nextafter(end, start);
                action |= MAR_SHAPE_ACT_REDUCED;
            }
        }
        if (action != 0) {
            ++infeasible;
            if (opt->policy == MAR_SHAPE_REJECT)
                action |= MAR_SHAPE_ACT_REJECTED;
        }
        double duration = (double)(b->tick - depart) * T;           /* [s] */
        r = mar_shape_plan_lag(start, end, (double)depart * T, duration, vmax, amax, lag,
                               &s->profile);
        if (r != 0)                             /* cannot happen: end is within reach */
            return r < 0 ? r : -EDOM;
        s->from_tick = a->tick;
        s->depart_tick = depart;
        s->arrive_tick = b->tick;
        s->target = b->value;
        s->reduced_by = fabs(b->value - end);
        s->action = action;
        s->reserved = 0;
        start = end;
    }
    open_turns(opt, seg, count);
    for (size_t i = 0; i < count; ++i) {
        const mar_shape_segment *s = &seg[i];
        double from = s->profile.x0;                      /* [unit] */
        for (int64_t k = s->from_tick; k <= s->depart_tick; ++k)     /* the hold */
            out[k] = from;
        for (int64_t k = s->depart_tick + 1; k < s->arrive_tick; ++k)  /* the move */
            out[k] = eval_local(&s->profile, (double)(k - s->depart_tick) * T, NULL, NULL);
        out[s->arrive_tick] = s->profile.x1;              /* the climax */
    }
    *n_seg = count;
    return infeasible;
}
