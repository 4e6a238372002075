/* Online moves: acceleration-limited (trapezoidal) profiles from the current
 * position and velocity to a target at rest, like Reflexxes Type II.
 *
 * A profile has three phases: constant acceleration a1 for t1, cruise for
 * t2, constant acceleration a3 for t3 ending at the target with velocity 0.
 * Planning is closed-form; evaluation is a few multiplications. */
#ifndef MAR_MOVE_H
#define MAR_MOVE_H

typedef struct {
    double x0, v0;          /* start position [unit] and velocity [unit/s] */
    double target;          /* end position [unit], reached at rest */
    double a1, t1;          /* first phase: acceleration [unit/s^2], duration [s] */
    double v2, t2;          /* cruise: velocity [unit/s], duration [s] */
    double a3, t3;          /* last phase: acceleration [unit/s^2], duration [s] */
} mar_move;

/* Time-optimal profile under |v| <= vmax, |a| <= amax; returns its duration
 * [s]. Assumes |v0| <= vmax (the engine's limits guarantee it); a faster
 * start is first slowed down at amax. */
double mar_move_plan(mar_move *m, double x0, double v0, double target, double vmax, double amax);

/* Profile from (x0, v0) to target at rest taking exactly duration [s],
 * accelerating at amax and cruising as slowly as that allows. Returns 0, or
 * -1 when no such profile exists (duration shorter than the optimum, or the
 * start velocity points away and no single-cruise profile fits); m is then
 * the time-optimal profile. */
int mar_move_plan_timed(mar_move *m, double x0, double v0, double target, double vmax,
                        double amax, double duration);

double mar_move_duration(const mar_move *m);                 /* [s] */

/* Position [unit] at time t [s] after the start, and velocity in *v. */
double mar_move_eval(const mar_move *m, double t, double *v);

#endif
