#include "mar_sample.h"

#include <math.h>

double mar_sample(const double *x, size_t n, double p, int interp, double *slope)
{
    if (n == 1 || !(p > 0.0)) {           /* also catches NaN p */
        *slope = 0.0;
        return x[0];
    }
    double last = (double)(n - 1);
    if (p >= last) {
        *slope = 0.0;
        return x[n - 1];
    }
    size_t i = (size_t)p;                 /* segment [i, i+1] */
    double f = p - (double)i;
    double x1 = x[i], x2 = x[i + 1];
    if (interp == MAR_INTERP_LINEAR) {
        *slope = x2 - x1;
        return x1 + f * (x2 - x1);
    }
    /* Catmull-Rom tangents; at the ends the missing neighbour is mirrored */
    double x0 = i > 0 ? x[i - 1] : 2.0 * x1 - x2;
    double x3 = i + 2 < n ? x[i + 2] : 2.0 * x2 - x1;
    double m1 = 0.5 * (x2 - x0), m2 = 0.5 * (x3 - x1);
    double d = x2 - x1;
    /* Hermite form x1 + f*(m1 + f*(b + f*c)) */
    double b = 3.0 * d - 2.0 * m1 - m2;
    double c = m1 + m2 - 2.0 * d;
    *slope = m1 + f * (2.0 * b + 3.0 * f * c);
    return x1 + f * (m1 + f * (b + f * c));
}
