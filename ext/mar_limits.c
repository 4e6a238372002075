#include "mar_limits.h"

#include <math.h>

double mar_brake_speed(double distance, double a, double T)
{
    if (distance <= 0.0)
        return 0.0;
    /* largest v >= 0 with v*T + v^2/(2a) <= distance */
    double aT = a * T;
    return -aT + sqrt(aT * aT + 2.0 * a * distance);
}

double mar_limit_step(const mar_limits *lim, double T, double x0, double v0,
                      double target, const double accel[2], double *v1, int *limited)
{
    double vmax = lim->max_speed, aT = lim->max_accel * T;
    double hi = vmax, lo = -vmax;
    double a_hi = accel ? accel[1] : v0 + aT, a_lo = accel ? accel[0] : v0 - aT;
    if (a_hi < hi)
        hi = a_hi;
    if (a_lo > lo)
        lo = a_lo;
    double up = mar_brake_speed(lim->pos_max - x0, lim->max_accel, T);
    double down = mar_brake_speed(x0 - lim->pos_min, lim->max_accel, T);
    if (up < hi)
        hi = up;
    if (-down > lo)
        lo = -down;

    /* a non-finite target is never followed: slow down to rest instead */
    int finite = isfinite(target);
    double want = finite ? (target - x0) / T : 0.0;
    double v = want;
    if (v > hi)
        v = hi;
    if (v < lo)           /* lo wins should rounding ever cross the bounds */
        v = lo;
    /* an unlimited step lands exactly on the target, bit for bit */
    double x1 = finite && v == want ? target : x0 + v * T;
    /* the braking bounds keep x1 inside; this only absorbs rounding */
    if (x1 > lim->pos_max)
        x1 = lim->pos_max;
    if (x1 < lim->pos_min)
        x1 = lim->pos_min;
    *limited = !finite || x1 != target;
    *v1 = (x1 - x0) / T;
    return x1;
}
