/* The follower's Kalman filter (mar_follow_kf.h). */
#include "mar_follow_kf.h"

void mar_kf_init(mar_kf *kf, double var_p, double var_r)
{
    kf->P00 = var_p;
    kf->P01 = 0.0;
    kf->P11 = var_r;
}

void mar_kf_predict(mar_kf *kf, double q_r)
{
    double p00 = kf->P00 + 2.0 * kf->P01 + kf->P11 + MAR_KF_Q_P;
    double p01 = kf->P01 + kf->P11;
    double p11 = kf->P11 + q_r;
    kf->P00 = p00, kf->P01 = p01, kf->P11 = p11;
    kf->p += kf->r;
}

double mar_kf_lag_var(const mar_kf *kf, double c)
{
    double hp0 = kf->P00 - c * kf->P01, hp1 = kf->P01 - c * kf->P11;     /* P H' */
    return hp0 - c * hp1;
}

void mar_kf_update(mar_kf *kf, double c, double d, double R)
{
    double hp0 = kf->P00 - c * kf->P01, hp1 = kf->P01 - c * kf->P11;     /* P H' */
    double S = hp0 - c * hp1 + R;                                         /* H P H' + R */
    double k0 = hp0 / S, k1 = hp1 / S;                                    /* the gain */
    kf->p += k0 * d;
    kf->r += k1 * d;
    kf->P00 -= k0 * hp0;
    kf->P01 -= k0 * hp1;
    kf->P11 -= k1 * hp1;
}
