/* A servo's drive as the engine predicts it: a first-order lag with a
 * limited speed, following the command it holds (the behaviour model; its
 * dead time only shifts the motion in time, so it does not appear here).
 *
 * While an input u is held, the drive's velocity is (u - y) / tau, clipped
 * to +-vmax: it runs at vmax while the gap is wider than vmax * tau, then
 * closes the gap exponentially. Both have closed forms, so predicting a
 * tick is a few multiplications and one exp(). */
#ifndef MAR_LAG_H
#define MAR_LAG_H

#include <stdint.h>

typedef struct {
    double tau;         /* lag time constant [s]; 0: the drive runs to its input at vmax */
    double vmax;        /* top speed [unit/s], > 0 */
    double period;      /* tick period: how long each command is held [s] */
    double y;           /* predicted position when the next command takes effect [unit] */
    double v;           /* its velocity over the tick before then [unit/s] */
    double gap[2];      /* input - position at the start of the tick before ([1]) and of the one
                         * before that ([0]) [unit]: how the drive moved within them */
} mar_lag;

/* Hold input [unit] for periods ticks: y and v move on by the model. */
void mar_lag_hold(mar_lag *m, double input, int64_t periods);

/* The input [unit] that, held for one tick, moves the drive by move [unit]
 * from y (a move beyond vmax * period: the input that runs it at vmax). */
double mar_lag_input(const mar_lag *m, double move);

/* A stop's next input [unit] (*input), for a profile that has the drive at
 * goal [unit] after the next tick and at after [unit] one tick later, with
 * the drive's acceleration within amax [unit/s^2] as measured at the scale
 * of a tick at every instant: its move over the tick ending then less its
 * move over the tick before, / T^2. Within a tick the drive runs at top
 * speed for a while and then decays towards its input, so that measure
 * can exceed amax between the ticks where the ticks' own positions do not.
 * window: the inputs that keep it within amax (window[0] <= window[1]; if
 * none does, the motion before having asked too much: those that keep it
 * so at the tick's end). Returns 0 when the profile is followed (the input
 * that lands on goal, from which the next tick can land on after); 1 when
 * not: then the input in window that, with the hardest braking the next
 * tick allows, brakes the most over the two ticks, but no more than the
 * profile does. */
int mar_lag_stop_input(const mar_lag *m, double amax, double goal, double after, double window[2],
                       double *input);

#endif
