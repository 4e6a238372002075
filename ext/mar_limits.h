/* Hard limits on a command stream: position, velocity and acceleration.
 *
 * Each tick the new command is x1 = x0 + v*T with v chosen as close as
 * possible to the wanted velocity inside the intersection of
 *   |v| <= vmax, |v - v0| <= amax*T, and the braking bounds
 *   x0 + v*T + v^2/(2*amax) <= pos_max (and the mirror image at pos_min),
 * so the stream can always stop before a position limit. Starting at rest
 * inside the limits, that intersection is never empty (see
 * docs/architecture.md), so no limit is ever traded against another. */
#ifndef MAR_LIMITS_H
#define MAR_LIMITS_H

typedef struct {
    double pos_min;     /* lower position limit [m or rad] */
    double pos_max;     /* upper position limit [m or rad] */
    double max_speed;   /* top speed [unit/s], > 0 */
    double max_accel;   /* top acceleration [unit/s^2], > 0 */
} mar_limits;

/* Highest speed [unit/s] at which a stream distance [unit] from a limit can
 * still stop in time, given one more tick of period T [s] at that speed. */
double mar_brake_speed(double distance, double max_accel, double period);

/* Next command [unit] towards target from command x0 moving at v0 [unit/s].
 * Writes the resulting velocity [unit/s] to *v1; returns the command.
 * *limited is set to 1 when the target could not be followed exactly.
 * accel: the command velocities [unit/s] the acceleration bound allows,
 * {lo, hi}; NULL: v0 -+ max_accel * period, the bound on the command itself. */
double mar_limit_step(const mar_limits *lim, double period, double x0, double v0,
                      double target, const double accel[2], double *v1, int *limited);

#endif
