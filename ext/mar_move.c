#include "mar_move.h"

#include <math.h>

static double sign(double x) { return x < 0.0 ? -1.0 : 1.0; }

double mar_move_duration(const mar_move *m) { return m->t1 + m->t2 + m->t3; }

/* Fill a profile in direction s (+1/-1) reaching peak speed up >= 0 along s. */
static void fill(mar_move *m, double x0, double v0, double target, double s, double up,
                 double amax, double cruise_time)
{
    double u0 = s * v0;                         /* start velocity along s [unit/s] */
    m->x0 = x0;
    m->v0 = v0;
    m->target = target;
    m->a1 = s * amax * sign(up - u0);
    m->t1 = fabs(up - u0) / amax;
    m->v2 = s * up;
    m->t2 = cruise_time > 0.0 ? cruise_time : 0.0;
    m->a3 = -s * amax;
    m->t3 = up / amax;
}

double mar_move_plan(mar_move *m, double x0, double v0, double target, double vmax, double amax)
{
    double d = target - x0;                     /* [unit] */
    double stop = v0 * fabs(v0) / (2.0 * amax); /* where braking now would end, relative [unit] */
    double s = d - stop != 0.0 ? sign(d - stop) : sign(v0);
    double D = s * d, u0 = s * v0;              /* along the direction of travel */
    if (u0 > vmax)
        u0 = vmax;                              /* outside the assumption: treat as vmax */
    /* no cruise: (up^2 - u0^2)/2a + up^2/2a = D */
    double up2 = amax * D + 0.5 * u0 * u0;
    double up = up2 > 0.0 ? sqrt(up2) : 0.0;
    double cruise = 0.0;
    if (up > vmax) {
        up = vmax;
        double d13 = (2.0 * vmax * vmax - u0 * u0) / (2.0 * amax);   /* accel + decel distance */
        cruise = (D - d13) / vmax;
    }
    fill(m, x0, s * u0, target, s, up, amax, cruise);
    m->v0 = v0;
    return mar_move_duration(m);
}

int mar_move_plan_timed(mar_move *m, double x0, double v0, double target, double vmax,
                        double amax, double T)
{
    double best = mar_move_plan(m, x0, v0, target, vmax, amax);
    if (!(T >= best))
        return -1;
    if (T == best)
        return 0;
    double d = target - x0;
    /* Try both directions; the profile must end at rest moving along s. */
    for (int k = 0; k < 2; k++) {
        double s = k == 0 ? sign(d) : -sign(d);
        double D = s * d, u0 = s * v0, a = amax;
        /* case up >= u0: up^2/a - up (T + u0/a) + (D + u0^2/2a) = 0, smaller root */
        double b = T + u0 / a;
        double disc = b * b - 4.0 * (D + u0 * u0 / (2.0 * a)) / a;
        if (disc >= 0.0) {
            double up = 0.5 * a * (b - sqrt(disc));
            double t1 = (up - u0) / a, t3 = up / a, t2 = T - t1 - t3;
            if (up >= 0.0 && up <= vmax && t1 >= 0.0 && t2 >= 0.0) {
                fill(m, x0, v0, target, s, up, a, t2);
                return 0;
            }
        }
        /* case 0 <= up <= u0: up = (D - u0^2/2a) / (T - u0/a) */
        if (u0 > 0.0 && T > u0 / a) {
            double up = (D - u0 * u0 / (2.0 * a)) / (T - u0 / a);
            double t1 = (u0 - up) / a, t3 = up / a, t2 = T - t1 - t3;
            if (up >= 0.0 && up <= u0 && up <= vmax && t2 >= 0.0) {
                fill(m, x0, v0, target, s, up, a, t2);
                return 0;
            }
        }
    }
    mar_move_plan(m, x0, v0, target, vmax, amax);
    return -1;
}

double mar_move_eval(const mar_move *m, double t, double *v)
{
    if (t <= 0.0) {
        *v = m->v0;
        return m->x0;
    }
    if (t >= mar_move_duration(m)) {
        *v = 0.0;
        return m->target;
    }
    double x = m->x0, vel = m->v0;
    double dt = t < m->t1 ? t : m->t1;         /* phase 1 */
    x += vel * dt + 0.5 * m->a1 * dt * dt;
    vel += m->a1 * dt;
    t -= dt;
    if (t > 0.0) {                              /* cruise */
        dt = t < m->t2 ? t : m->t2;
        x += m->v2 * dt;
        vel = m->v2;
        t -= dt;
    }
    if (t > 0.0) {                              /* phase 3, evaluated back from the end for exactness */
        double left = m->t3 - t;                /* time until arrival [s] */
        *v = -m->a3 * left;
        return m->target - 0.5 * (-m->a3) * left * left;
    }
    *v = vel;
    return x;
}
