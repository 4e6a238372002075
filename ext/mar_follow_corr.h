/* Correlation of a live window against the stored music at whole-frame
 * lags, and the peak of those correlations: what every measurement of the
 * follower (tracking, verification, the cue's fits, the near search) is
 * made of.
 *
 * The stored side comes with its prefix sums (q1[i] = sum of stored[0 ..
 * i), q2 the same of squares), so each lag costs one dot product: the
 * stored window's mean and spread are two differences.
 *
 * Plain C11, no allocation; the step of ext/mar_follow.c uses it. */
#ifndef MAR_FOLLOW_CORR_H
#define MAR_FOLLOW_CORR_H

#include <stddef.h>

/* Pearson correlation of live[0 .. len) with stored[at + d .. at + d +
 * len), for d = -lags .. lags, into rho[d + lags] (0 where either side is
 * flat). stored[at - lags .. at + lags + len) and q1, q2 up to index at +
 * lags + len must exist. Returns the live window's spread (its standard
 * deviation, in the unit of live: [dB] for the loudness feature). */
double mar_corr_lags(const double *live, size_t len, const double *stored, const double *q1,
                     const double *q2, long at, int lags, double *rho);

/* The peak of rho[0 .. 2 lags]: its lag [ticks] from the centre, refined
 * by a parabola through the best lag and its neighbours (at most half a
 * tick), *height the parabola's top, *kappa its curvature [1/tick^2], and
 * *edge 1 when the best lag is at either end (no peak: kappa 0, the lag
 * not refined). */
double mar_corr_peak(const double *rho, int lags, double *height, double *kappa, int *edge);

#endif
