#include "mar_clock.h"

void mar_clock_set(mar_clock *c, double position, double rate)
{
    c->position = position;
    c->rate = rate;
    c->change = 0.0;
}

static double clamp(double v, double bound)
{
    return v < -bound ? -bound : v > bound ? bound : v;
}

void mar_clock_follow(mar_clock *c, double position, double rate, double period, double catch_up)
{
    const double w = MAR_CLOCK_OMEGA * period;      /* the poles per tick [1/tick] */
    if (!(catch_up >= MAR_CLOCK_MIN_CATCH_UP))
        catch_up = MAR_CLOCK_MIN_CATCH_UP;
    /* a far position error counts as this much: the tracker then runs at the
     * music's rate + catch_up, where its jerk w^3 e + 3 w^2 u is 0 */
    const double far = 3.0 * catch_up / w;          /* [show ticks] */
    if (c->rate == 0.0 && c->change == 0.0)         /* standing: start at the music's rate */
        c->rate = rate;
    c->position += c->rate;
    double e = clamp(position - c->position, far), u = clamp(rate - c->rate, MAR_CLOCK_RATE_STEP);
    c->change += w * w * w * e + 3.0 * w * w * u - 3.0 * w * c->change;
    c->rate += c->change;
    if (c->rate < 0.0) {                            /* the show never plays backwards */
        c->change -= c->rate;
        c->rate = 0.0;
    }
}
