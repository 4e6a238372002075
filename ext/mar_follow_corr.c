/* Correlation at lags and its peak (mar_follow_corr.h). */
#include "mar_follow_corr.h"

#include <math.h>

double mar_corr_lags(const double *live, size_t len, const double *stored, const double *q1,
                     const double *q2, long at, int lags, double *rho)
{
    double lm = 0.0;
    for (size_t k = 0; k < len; k++)
        lm += live[k];
    lm /= (double)len;
    double ll = 0.0;
    for (size_t k = 0; k < len; k++)
        ll += (live[k] - lm) * (live[k] - lm);
    for (int d = -lags; d <= lags; d++) {
        long js = at + d;
        const double *s = stored + js;
        double a0 = 0.0, a1 = 0.0, a2 = 0.0, a3 = 0.0;
        size_t k = 0;
        for (; k + 4 <= len; k += 4) {                 /* four sums: independent adds */
            a0 += (live[k] - lm) * s[k];
            a1 += (live[k + 1] - lm) * s[k + 1];
            a2 += (live[k + 2] - lm) * s[k + 2];
            a3 += (live[k + 3] - lm) * s[k + 3];
        }
        for (; k < len; k++)
            a0 += (live[k] - lm) * s[k];
        double cov = a0 + a1 + a2 + a3;
        size_t q = (size_t)js;
        double s1 = q1[q + len] - q1[q], s2 = q2[q + len] - q2[q];
        double ss = s2 - s1 * s1 / (double)len;
        rho[d + lags] = (ll > 1e-9 && ss > 1e-9) ? cov / sqrt(ll * ss) : 0.0;
    }
    return sqrt(ll / (double)len);
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
