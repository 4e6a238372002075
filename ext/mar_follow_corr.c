/* Correlation along a line (mar_follow_corr.h). */
#include "mar_follow_corr.h"

#include <math.h>

size_t mar_corr_resample(const mar_corr_history *live, size_t ages, double p, double r, long lo, long hi,
                         size_t cap, double *out, long *j0, double *center)
{
    if (ages < 2 || !(r > 0.0))
        return 0;
    double xa = p - r * ((double)(ages - 1) + 0.5) - 0.5;     /* oldest frame's stored index */
    double xb = p - r * 0.5 - 0.5;                             /* newest */
    long ja = (long)ceil(xa), jb = (long)floor(xb);
    if (jb < ja)
        return 0;
    size_t m = (size_t)(jb - ja + 1);
    if (m > cap)
        m = cap, ja = jb - (long)m + 1;
    if (ja < lo || jb > hi)
        return 0;
    const size_t nb = live->bands;
    double csum = 0.0;
    size_t valid = 0;
    for (size_t k = 0; k < m; k++) {
        double a = (p - 0.5 - (double)(ja + (long)k)) / r - 0.5;   /* live age of this stored frame */
        if (a < 0.0)
            a = 0.0;
        size_t i0 = (size_t)a;
        double fr = a - (double)i0;
        const double *v0 = live->v + ((live->t - i0) & live->mask) * nb;
        const double *v1 = fr > 0.0 && i0 + 1 < ages ? live->v + ((live->t - (i0 + 1)) & live->mask) * nb : v0;
        for (size_t b = 0; b < nb; b++)
            out[b * cap + k] = v0[b] + fr * (v1[b] - v0[b]);        /* NaN when either is missing */
        if (!isnan(out[k])) {
            csum += a + 0.5;
            valid++;
        }
    }
    if (valid < 2)
        return 0;
    for (size_t b = nb; b-- > 0;) {          /* band 0, which marks the missing frames, last */
        double *o = out + b * cap, sum = 0.0;
        for (size_t k = 0; k < m; k++)
            if (!isnan(out[k]))
                sum += o[k];
        double mean = sum / (double)valid;
        for (size_t k = 0; k < m; k++)
            o[k] = isnan(out[k]) ? 0.0 : o[k] - mean;
    }
    *j0 = ja;
    *center = csum / (double)valid;
    return m;
}

/* Band b's sum of squares about its mean over the stored frames at .. at
 * + len - 1, from the prefix sums. */
static double stored_ss(const mar_corr_stored *stored, size_t b, long at, size_t len)
{
    const double *q1 = stored->q1 + b * (stored->stride + 1), *q2 = stored->q2 + b * (stored->stride + 1);
    size_t q = (size_t)at;
    double s1 = q1[q + len] - q1[q];
    return q2[q + len] - q2[q] - s1 * s1 / (double)len;
}

double mar_corr_lags(const double *live, size_t cap, size_t len, const mar_corr_stored *stored, long at,
                     int lags, double *rho)
{
    const size_t nb = stored->bands;
    double lm[MAR_CORR_MAX_BANDS], lsd[MAR_CORR_MAX_BANDS], ll = 0.0;   /* lsd: sqrt of each band's ss */
    for (size_t b = 0; b < nb; b++) {
        const double *l = live + b * cap;
        double sum = 0.0, ss = 0.0;
        for (size_t k = 0; k < len; k++)
            sum += l[k];
        lm[b] = sum / (double)len;
        for (size_t k = 0; k < len; k++)
            ss += (l[k] - lm[b]) * (l[k] - lm[b]);
        lsd[b] = sqrt(ss);
        ll += ss;
    }
    for (int d = -lags; d <= lags; d++) {
        long js = at + d;
        double num = 0.0, wsum = 0.0;      /* sum of sqrt(ss_b) rho_b, sum of sqrt(ss_b) */
        for (size_t b = 0; b < nb; b++) {
            const double *l = live + b * cap, *s = stored->v + b * stored->stride + js, m = lm[b];
            double a0 = 0.0, a1 = 0.0, a2 = 0.0, a3 = 0.0;
            size_t k = 0;
            for (; k + 4 <= len; k += 4) {             /* four sums: independent adds */
                a0 += (l[k] - m) * s[k];
                a1 += (l[k + 1] - m) * s[k + 1];
                a2 += (l[k + 2] - m) * s[k + 2];
                a3 += (l[k + 3] - m) * s[k + 3];
            }
            for (; k < len; k++)
                a0 += (l[k] - m) * s[k];
            double ss = stored_ss(stored, b, js, len);
            if (lsd[b] > sqrt(1e-9) && ss > 1e-9) {   /* a band flat on either side says nothing */
                num += (a0 + a1 + a2 + a3) / lsd[b];
                wsum += sqrt(ss);
            }
        }
        rho[d + lags] = wsum > 0.0 ? num / wsum : 0.0;
    }
    return sqrt(ll / ((double)len * (double)nb));
}

double mar_corr_slope_center(const mar_corr_stored *stored, long at, size_t len)
{
    double wsum = 0.0, ksum = 0.0;
    for (size_t b = 0; b < stored->bands; b++) {
        const double *s = stored->v + b * stored->stride + at;
        double ss = stored_ss(stored, b, at, len);
        if (!(ss > 1e-9))
            continue;                                  /* flat: no slope to tell a lag by */
        double norm = 1.0 / sqrt(ss);
        for (size_t k = 1; k + 1 < len; k++) {
            double g = 0.5 * (s[k + 1] - s[k - 1]), w = g * g * norm;
            wsum += w;
            ksum += w * (double)k;
        }
    }
    return wsum > 0.0 ? ksum / wsum : 0.5 * (double)(len - 1);
}

double mar_corr_peak(const double *rho, int lags, double *height, double *kappa, int *edge)
{
    int b = 0;
    for (int i = 1; i <= 2 * lags; i++)
        if (rho[i] > rho[b])
            b = i;
    *height = rho[b];
    *edge = b == 0 || b == 2 * lags;
    if (*edge) {
        *kappa = 0.0;
        return (double)(b - lags);
    }
    double y0 = rho[b - 1], y1 = rho[b], y2 = rho[b + 1];
    double den = y0 - 2.0 * y1 + y2;
    *kappa = -den;
    double off = den < 0.0 ? 0.5 * (y0 - y2) / den : 0.0;
    if (off > 0.5)
        off = 0.5;
    if (off < -0.5)
        off = -0.5;
    *height = y1 - 0.25 * (y0 - y2) * off;
    return (double)(b - lags) + off;
}
