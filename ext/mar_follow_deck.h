/* The tape deck as the follower believes it to be: a small probabilistic
 * model where the smooth mode has rules (issue 21). Two beliefs, each
 * updated from the live music:
 *
 *   motion: the deck plays or stands still, a two-state hidden Markov
 *     model whose evidence is each frame's level: hiss at the noise floor
 *     (stopped), or the stored music at the place, plus the volume, over
 *     that hiss (playing);
 *   place: which of a few places (the one followed, the whole-piece
 *     search's candidates, or somewhere else) the music of the last window
 *     comes from, with each place's band correlation as its likelihood and
 *     a prior that makes a jump rare.
 *
 * A quiet passage needs no hypothesis of its own: where the stored music is
 * as quiet as the hiss, a frame is evidence for neither motion, and where
 * the live window is flat it favours no place; both beliefs then stay where
 * they were and the position runs on at the rate.
 *
 * Plain C11, no allocation: the arithmetic of the beliefs only; the follower
 * (ext/mar_follow.c, mode MAR_FOLLOW_MODEL) measures the evidence. */
#ifndef MAR_FOLLOW_DECK_H
#define MAR_FOLLOW_DECK_H

#include <stddef.h>

/* --- motion ----------------------------------------------------------- */

typedef struct {
    double log_odds;            /* log P(stopped) - log P(playing) [1] */
    double stop_hazard;         /* P(a playing deck stops within a frame) [1] */
    double start_hazard;        /* P(a stopped deck starts within a frame) [1] */
} mar_deck_motion;

/* A fresh belief: P(stopped) = p_stopped; the hazards are per frame (0 .. 1). */
void mar_deck_motion_init(mar_deck_motion *m, double p_stopped, double stop_hazard, double start_hazard);

/* The evidence of one live frame, log p(db | stopped) - log p(db | playing)
 * [1]: stopped, the frame is hiss at floor_db; playing, it is the music
 * expected there (expected_db: the stored level at the place plus the
 * volume) over that hiss, their powers added. Both with the spread
 * sigma_db, each frame's evidence capped at +-cap so that one odd frame (a
 * dropout, a click) does not decide. Where the two predictions lie closer
 * than sigma_db (the music expected is about as quiet as the hiss), the
 * evidence is 0. [dB] in, NaN db: 0. */
double mar_deck_level_evidence(double db, double expected_db, double floor_db, double sigma_db, double cap);

/* The evidence of a live frame at db [dB] while the deck is believed
 * stopped, log p(db | stopped) - log p(db | playing) [1]: stopped, the
 * frame is the hiss heard since the stop (hiss_db, with the spread
 * hiss_sigma_db); playing, it is music anywhere from the hiss up to
 * span_db over it, whatever the volume knob did meanwhile. Capped at
 * +-cap; NaN db: 0. */
double mar_deck_hiss_evidence(double db, double hiss_db, double hiss_sigma_db, double span_db, double cap);

/* One frame: the deck may stop or start (the hazards), then the evidence
 * (mar_deck_level_evidence) weighs in. */
void mar_deck_motion_update(mar_deck_motion *m, double evidence);

/* P(stopped) [1]. */
double mar_deck_stopped(const mar_deck_motion *m);

/* --- place ------------------------------------------------------------ */

/* The log-likelihood [1] of a place whose line correlates rho with a live
 * window of n_eff independent values: the live window as the stored one
 * scaled plus Gaussian noise, its scale and offset fitted (the profile
 * likelihood), -(n_eff / 2) log(1 - rho^2). 0 for rho <= 0 or NaN (no
 * evidence); rho is taken as at most 0.999 (the noise is never 0). */
double mar_deck_place_evidence(double rho, double n_eff);

/* The posterior [1] of n places (log_w[i]: log prior + evidence) and of
 * "somewhere else" (log_w_else), which together make 1: post[i] for the
 * places, the return value for somewhere else. */
double mar_deck_posterior(const double *log_w, size_t n, double log_w_else, double *post);

#endif
