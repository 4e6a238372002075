/* Correlation along a line: the live history resampled onto the stored
 * frames a hypothesis (position p, rate r) says it played, correlated with
 * the stored music at whole-frame lags around it, and the peak of those
 * correlations. What every measurement of the follower (tracking,
 * verification, the cue's fits, the near search) is made of.
 *
 * The line. "The live music is at stored position p now and moves at rate
 * r" maps the live frame of age i (0 = newest, covering live time [now - i
 * - 1, now - i) [ticks]) to the stored index x(i) = p - r (i + 0.5) - 0.5
 * (stored frame j covers [j, j + 1)). A peak at lag d means the line is d
 * ticks behind where the music says.
 *
 * The stored side comes with its prefix sums (q1[i] = sum of stored[0 ..
 * i), q2 the same of squares), so each lag costs one dot product: the
 * stored window's mean and spread are two differences.
 *
 * Plain C11, no allocation; the step of ext/mar_follow.c uses it. */
#ifndef MAR_FOLLOW_CORR_H
#define MAR_FOLLOW_CORR_H

#include <stddef.h>
#include <stdint.h>

/* Bands. A feature may have several values per frame (the level in a few
 * frequency bands). Each band is correlated on its own (Pearson: its mean
 * and spread out per window, so a volume knob and a fixed colouring, a
 * constant offset per band, are ignored, and a band whose live swing the
 * hiss has compressed keeps its say), and the bands' correlations are
 * averaged, weighted by the stored window's spread in each: a band at its
 * stored floor tells little. A band flat on either side is left out; 0
 * when every band is. One band is the plain Pearson correlation. */

#define MAR_CORR_MAX_BANDS 8     /* values per frame, at most */

/* The live history as a ring: v[(step & mask) * bands + b] is band b of
 * the frame of that step (NaN: none came), t the newest step. */
typedef struct {
    const double *v;
    size_t mask;                /* ring size - 1 (a power of 2) */
    uint64_t t;                 /* newest step */
    size_t bands;               /* values per frame, >= 1 */
} mar_corr_history;

/* The stored side: band b's frame j at v[b * stride + j], its prefix sums
 * q1[b * (stride + 1) + q] = sum of v[b * stride + 0 .. q), q2 the same of
 * squares. */
typedef struct {
    const double *v, *q1, *q2;
    size_t stride;              /* frames per band [1] */
    size_t bands;               /* as the live side's */
} mar_corr_stored;

/* The live frames of ages 0 .. ages - 1 resampled along the line (p, r)
 * onto whole stored frames j0 .. j0 + m - 1 (linear between live frames),
 * at most cap, the newest kept; band b into out[b * cap ..], its mean
 * removed, missing frames at the mean (they add nothing to a covariance).
 * Returns m, 0 when fewer than 2 values or the frames would leave [lo,
 * hi]; *center: the mean (age + 0.5) of the samples [ticks], the window's
 * centre in the past. */
size_t mar_corr_resample(const mar_corr_history *live, size_t ages, double p, double r, long lo, long hi,
                         size_t cap, double *out, long *j0, double *center);

/* The correlation (above) of live[b * cap + 0 .. len) with the
 * stored frames at + d .. at + d + len of every band, for d = -lags ..
 * lags, into rho[d + lags] (0 where either side is flat). Stored frames at
 * - lags .. at + lags + len and their prefix sums must exist. Returns the
 * live window's spread (the root mean square over bands of each band's
 * standard deviation, in the unit of live: [dB] for the level features). */
double mar_corr_lags(const double *live, size_t cap, size_t len, const mar_corr_stored *stored, long at,
                     int lags, double *rho);

/* Where in a window of len stored frames (at + 0 .. len - 1, every band)
 * a lag measured on it comes from: the mean frame index k in [0, len - 1]
 * weighted by the stored feature's squared slope there (central
 * differences; each band over the root of its spread, as mar_corr_lags
 * weighs the bands). A correlation's lag is a mean of the local lags
 * weighted so, and a change of the music tells the lag where it changes:
 * one onset in a window puts it at the onset, not the window's middle.
 * (len - 1) / 2 when the window is flat. Stored frames at .. at + len and
 * their prefix sums must exist. */
double mar_corr_slope_center(const mar_corr_stored *stored, long at, size_t len);

/* The peak of rho[0 .. 2 lags]: its lag [ticks] from the centre, refined
 * by a parabola through the best lag and its neighbours (at most half a
 * tick), *height the parabola's top, *kappa its curvature [1/tick^2], and
 * *edge 1 when the best lag is at either end (no peak: kappa 0, the lag
 * not refined). */
double mar_corr_peak(const double *rho, int lags, double *height, double *kappa, int *edge);

#endif
