/* The follower's Kalman filter: position p [stored ticks] and rate r
 * [stored ticks per tick] of the live music, one predict per tick, and an
 * update from a correlation lag measured over a window whose centre lies c
 * ticks in the past.
 *
 * Model. State x = (p, r), F = [1 1; 0 1] per tick, process noise on the
 * rate (q_r per tick) and a whisker on the position (MAR_KF_Q_P) so that P
 * stays positive definite. A window centred c ticks ago measured the lag
 * d between the line (p, r) and the music; a position error e_p and a rate
 * error e_r make d = e_p - c e_r, so H = [1, -c].
 *
 * Plain C11, no allocation; the step of ext/mar_follow.c uses it. */
#ifndef MAR_FOLLOW_KF_H
#define MAR_FOLLOW_KF_H

#define MAR_KF_Q_P 1e-6         /* position process noise per tick [tick^2] */

typedef struct {
    double p, r;                /* [stored ticks], [stored ticks per tick] */
    double P00, P01, P11;       /* covariance of (p, r) [tick^2, tick^2 per tick, (per tick)^2] */
} mar_kf;

/* A fresh covariance: var_p [tick^2], var_r [(per tick)^2], uncorrelated. */
void mar_kf_init(mar_kf *kf, double var_p, double var_r);

/* One tick: p += r, P = F P F' + diag(MAR_KF_Q_P, q_r). */
void mar_kf_predict(mar_kf *kf, double q_r);

/* The predicted variance of a lag measured c ticks in the past: H P H'
 * with H = [1, -c] [tick^2]. */
double mar_kf_lag_var(const mar_kf *kf, double c);

/* The update with the lag d [ticks] measured c ticks in the past, with
 * measurement variance R [tick^2]. */
void mar_kf_update(mar_kf *kf, double c, double d, double R);

#endif
