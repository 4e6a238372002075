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
} mar_lag;

/* Hold input [unit] for periods ticks: y and v move on by the model. */
void mar_lag_hold(mar_lag *m, double input, int64_t periods);

/* The input [unit] that, held for one tick, moves the drive by move [unit]
 * from y (a move beyond vmax * period: the input that runs it at vmax). */
double mar_lag_input(const mar_lag *m, double move);

#endif
