/* Sampling a taught trajectory at a fractional show position. */
#ifndef MAR_SAMPLE_H
#define MAR_SAMPLE_H

#include <stddef.h>

enum mar_interp {
    MAR_INTERP_LINEAR = 0,   /* straight lines between samples */
    MAR_INTERP_CUBIC = 1,    /* Catmull-Rom cubic: C1, passes through every sample */
};

/* Value of samples x[0..n-1] at position p [ticks], and its slope [unit/tick]
 * in *slope. p outside [0, n-1] holds the end value with zero slope. */
double mar_sample(const double *x, size_t n, double p, int interp, double *slope);

#endif
