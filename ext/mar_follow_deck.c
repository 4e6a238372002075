/* The tape deck's beliefs (see mar_follow_deck.h). */
#include "mar_follow_deck.h"

#include <math.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

#define MAX_LOG_ODDS 30.0       /* certainty kept finite, so that evidence can always turn it [1] */
#define MAX_RHO 0.999           /* the best fit a window can show: its noise is never 0 [1] */

void mar_deck_motion_init(mar_deck_motion *m, double p_stopped, double stop_hazard, double start_hazard)
{
    double p = fmin(fmax(p_stopped, 1e-12), 1.0 - 1e-12);
    m->log_odds = log(p) - log1p(-p);
    m->stop_hazard = stop_hazard;
    m->start_hazard = start_hazard;
}

double mar_deck_level_evidence(double db, double expected_db, double floor_db, double sigma_db, double cap)
{
    if (isnan(db) || isnan(expected_db) || isnan(floor_db) || !(sigma_db > 0.0))
        return 0.0;
    /* playing: the music over the hiss, powers added; stopped: the hiss */
    double hi = fmax(expected_db, floor_db), lo = fmin(expected_db, floor_db);
    double playing = hi + 10.0 * log10(1.0 + pow(10.0, 0.1 * (lo - hi)));     /* [dB] */
    /* closer than the spread, the two are one prediction: where the music is
     * as quiet as the hiss, no frame tells them apart (and a small error in
     * either level, repeated frame after frame, would add up to a stop) */
    if (fabs(playing - floor_db) < sigma_db)
        return 0.0;
    double a = db - playing, b = db - floor_db;                                 /* [dB] */
    double ev = (a * a - b * b) / (2.0 * sigma_db * sigma_db);
    return fmax(-cap, fmin(cap, ev));
}

double mar_deck_hiss_evidence(double db, double hiss_db, double hiss_sigma_db, double span_db, double cap)
{
    if (isnan(db) || isnan(hiss_db) || !(hiss_sigma_db > 0.0) || !(span_db > 0.0))
        return 0.0;
    double z = (db - hiss_db) / hiss_sigma_db;
    double stopped = -0.5 * z * z - log(hiss_sigma_db * sqrt(2.0 * M_PI));     /* log density [1/dB] */
    double playing = db >= hiss_db ? -log(span_db) : -INFINITY;                   /* uniform over the span */
    return fmax(-cap, fmin(cap, stopped - playing));
}

void mar_deck_motion_update(mar_deck_motion *m, double evidence)
{
    /* the deck may have stopped or started since the last frame ... */
    double p = mar_deck_stopped(m);
    double q = p * (1.0 - m->start_hazard) + (1.0 - p) * m->stop_hazard;
    q = fmin(fmax(q, 1e-13), 1.0 - 1e-13);
    /* ... then this frame's evidence */
    double lo = log(q) - log1p(-q) + evidence;
    m->log_odds = fmax(-MAX_LOG_ODDS, fmin(MAX_LOG_ODDS, lo));
}

double mar_deck_stopped(const mar_deck_motion *m) { return 1.0 / (1.0 + exp(-m->log_odds)); }

double mar_deck_place_evidence(double rho, double n_eff)
{
    if (!(rho > 0.0) || !(n_eff > 0.0))
        return 0.0;
    double r = fmin(rho, MAX_RHO);
    return -0.5 * n_eff * log1p(-r * r);
}

double mar_deck_posterior(const double *log_w, size_t n, double log_w_else, double *post)
{
    double top = log_w_else;
    for (size_t i = 0; i < n; i++)
        top = fmax(top, log_w[i]);
    double sum = exp(log_w_else - top);
    for (size_t i = 0; i < n; i++)
        sum += post[i] = exp(log_w[i] - top);
    for (size_t i = 0; i < n; i++)
        post[i] /= sum;
    return exp(log_w_else - top) / sum;
}
