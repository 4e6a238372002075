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
