/* Music following: live loudness against stored loudness, every tick.
 *
 * The feature. Both streams go through the same causal map, frame by
 * frame: loudness x (linear) -> level L = 20 log10(x) [dB] -> clamped at a
 * running peak level minus range_db (quieter detail, hum and noise do not
 * matter). The volume knob adds a constant to L, which the correlation
 * (Pearson: means and spreads removed per window) ignores. With band
 * levels each band goes through the same map on its own, and the
 * correlations average each band's own (mar_follow_corr.h: a fixed
 * colouring is ignored too; the search's coarse blocks correlate jointly
 * over the bands) wherever the newest frame brought as many bands as the
 * show has ("the main channel");
 * the level logic (pause, onset, floor, gain) stays on the loudness.
 *
 * The line. A hypothesis "the live music is at stored position p now and
 * moves at rate r" maps the live frame of age i (0 = newest, covering live
 * time [now - i - 1, now - i) [ticks]) to the stored frame index
 *     x(i) = p - r (i + 0.5) - 0.5        (stored frame j covers [j, j + 1))
 * The live history is resampled along that line onto whole stored frames,
 * then correlated with the stored feature at whole-frame lags d: a peak at
 * lag d means the hypothesis is d ticks behind where the window says. The
 * stored side's sums come from prefix sums, so each lag is one dot product.
 *
 * Tracking (smooth mode). State (p, r) with a Kalman filter: predict p += r;
 * measure the lag d* (peak of the correlation over lags -3..3, refined by a
 * parabola to a fraction of a tick) whose window has its centre c ticks in
 * the past, so the measurement model is d* = e_p - c e_r (H = [1, -c]).
 * The measurement's variance grows when the correlation peak is flat
 * (quiet, sustained music), so such windows barely move the estimate; a
 * window that is too quiet, correlates too little or lands outside the
 * gate is not used: the position runs on at the rate (flywheel, HOLDING).
 * Once a bad stretch has started the search beside, REGAIN_S of fitting
 * measurements in a row end the hold, not one.
 *
 * Paper mode. Same correlation at lags -1, 0, +1 and rate 1: the position
 * (whole ticks) advances by 0, 1 or 2, i.e. one stored sample is doubled
 * or skipped.
 *
 * Search. When not locked: the stored feature is averaged over blocks of
 * `coarse` ticks; the newest search_window blocks of live audio are resampled
 * for each rate of a grid (rate_min .. rate_max by rate_step) and scored
 * against every block offset of the piece, search_budget (offset, rate)
 * pairs per tick, so a sweep of the whole piece takes a few ticks. The
 * best places go into a small pool; every tick one pool entry is verified
 * at full resolution: two half windows each give a lag, which corrects
 * both its position and its rate, and their correlation is its score.
 * Lock when one place is good enough (lock_threshold, a sharp peak), was
 * verified twice in a row without a large correction, has lock_window live
 * frames behind it, and leads every other distinct place by lock_margin in
 * Fisher's z (more for windows shorter than verify_window: a short window
 * proves less), each rival scored again on the very live frames behind the
 * place (a score from a shorter window runs higher), the last sweep's best
 * places among the rivals even when the pool had no room for them, after
 * at least one whole sweep: a repeated section with a near twin elsewhere
 * does not lock until the music tells them apart. With onsets, the line a
 * lock takes moves halfway to the one the onset feature's half windows
 * measure (second_opinion).
 *
 * Pause. Where the stored music says the live frame should stand clearly
 * over the noise floor (the quietest live frame of the last 20 s, moved
 * with the live-minus-stored level, as the hiss on the tape turns with the
 * volume knob), frames far below that, near the floor (or very far below)
 * and steady like hiss, for pause_after ticks: the recorder stopped. A
 * stop the gain estimate cannot show (it lags a knob turned just before
 * or during it) is the level falling onto a line that stands still for
 * 0.5 s while the music expected there moves (stands_still). This
 * runs while the place is LOCKED or HOLDING on the flywheel (a quiet
 * passage or a volume turn can make the tracking unclear just before a
 * stop), not in doubt (below). The position goes back to where the silence
 * began and holds (rate 0). Two frames clearly above the silence (by a few
 * of its own frame-to-frame wobbles) resume it there, from the start of the
 * rise; the resumed place is on probation (HOLDING, search beside). A near search
 * correlates the frames since the restart at lags of up to 1 s around it
 * and locks on a clear peak there (a deck that backs up on restart, a stop
 * placed a little late), or around the place the music would have
 * reached had the tape not stopped (a fade read as a stop); without one
 * the tracker confirms the place after NEAR_S. Silence or unclear
 * music in probation sends it to the whole-piece search: a jump into a
 * quiet passage does not loop through pauses.
 *
 * Doubt. A collapse of the tracking peak height (short-run average 0.25
 * under the long-run one) in clear music means the tape may have jumped to
 * alike music (the same drums elsewhere): HOLDING, and the search beside
 * (the tracker's place in its pool) decides by the lock rules. In doubt a
 * quiet break is not taken for a pause, with two exceptions: a collapse
 * that comes with a silent run already under way is the stop itself (no
 * doubt is raised), and one while the volume knob turns (the gain estimate
 * runs more than TURNING_DB ahead of its 1 s average) is the feature's
 * clamp lagging behind the knob, not a wrong place. */
#include "mar_follow.h"
#include "mar_follow_corr.h"
#include "mar_follow_deck.h"
#include "mar_follow_kf.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define POOL 16                 /* search candidates kept */
#define PEAKS 8                 /* a sweep's best places kept for the lock check, pool or not */
#define MAX_RATES 64            /* rate grid size limit */
#define TRACK_LAGS 3            /* tracking lags -3..3 [ticks] */
#define VERIFY_LAGS 6           /* verification lags -6..6 [ticks] */
#define WIDE_LAGS 12            /* tracking lags at most -12..12 [ticks] */
#define NEAR_LAGS 50            /* near search reach -50..50 (1 s either way) [ticks] */
#define NEAR_RIVAL_LAGS 150     /* ... and every place within 3 s either way is its rival [ticks] */
#define MAX_LAGS NEAR_RIVAL_LAGS
#define LEVEL_RELEASE 5.0       /* running peak level falls this fast [dB/s] */
#define TINY 1e-10              /* loudness floor before the logarithm [full scale] */
#define FLOOR_BLOCK_S 1.0       /* noise floor: minimum over blocks this long [s] ... */
#define FLOOR_BLOCKS 20         /* ... over the last this many blocks (20 s) */
#define LOW_DB 10.0             /* a frame this far below the expected level is "low" [dB] */
#define NEAR_FLOOR_DB 6.0       /* ... and this close to the noise floor is "silent" [dB] */
#define STEADY_DB 2.0           /* silence changes less than this from frame to frame [dB] */
#define MUSIC_RANGE_DB 40.0     /* stored frames this far below its loud level are not music [dB] */
#define DEEP_DB 20.0            /* ... or this far below the expected level [dB] */
#define AUDIBLE_DB 6.0          /* expected level this far over the floor counts as music [dB] */
#define RESUME_DB 10.0          /* a frame this far over the floor is music again [dB] */
#define RESUME_VAR 16.0         /* position variance after a resume [tick^2] */
#define PAUSE_ALPHA 0.2         /* the silence's level estimate, smoothing per REF_PERIOD [1] */
#define MIN_RESUME_DB 3.0       /* ... or less where the music is quiet, not below this [dB] */
#define LOUD_DB 15.0            /* stored frames within this of the stored level are loud: they count for the gain,
                                 * and only where they are heard may a cue be refuted [dB] */
#define GAIN_STEP 25.0          /* the gain estimate moves at most this fast [dB/s] */
#define GAIN_PRIOR 1.0          /* a lock's gain: the gain before it weighs as this much loud music [s] */
#define GAIN_ALPHA 0.1          /* live-minus-stored gain estimate smoothing per REF_PERIOD [1] */
#define GAIN_SLOW_ALPHA 0.02    /* ... and its slow twin's (a time constant of 1 s) [1] */
#define TURNING_DB 2.0          /* the two this far apart: the volume knob is turning [dB] */
#define DISTINCT 25.0           /* candidates this far apart are different places [ticks] */
#define TRACK_SEP 4.0           /* ... but the tracker's own entry stands only for its tracking lags [ticks] */
#define MIN_SEARCH_BLOCKS 12    /* fewest live blocks before the search scores anything */
#define SEARCH_MIN_SCORE 0.3    /* coarse score worth a pool entry [1] */
#define COARSE_SLACK 0.15       /* unverified entries within this of the best are verified before a lock */
#define VERIFIED_BONUS 0.1      /* see cand_rank [1] */
#define LOCK_CONFIRM 2          /* consecutive small verifications before a lock */
#define KAPPA_REF 0.05          /* correlation curvature of a clear peak [1/tick^2] */
#define KAPPA_LOCK_Z 0.08       /* a lock needs peaks at least this sharp in both halves, in Fisher z
                                 * (curvature / (1 - rho^2): near rho = 1 a slight drop is a clear one) [1/tick^2] */
#define STEADY_RANGE_DB 3.0     /* a pause's frames stay within this range (hiss), music moves more [dB] */
#define H_SLOW 0.003            /* tracking peak height: long-run average, per measurement and REF_PERIOD [1] */
#define H_FAST 0.1              /* ... short-run average, per measured (not quiet) REF_PERIOD [1] */
#define DOUBT_DROP 0.25         /* short-run height this far under the long-run one: doubt the place, at most [1] */
#define DOUBT_DROP_MIN 0.1      /* ... at least [1] */
#define DOUBT_SIGMAS 4.0        /* ... else this many of the heights' own long-run deviations [1] */
#define CLEAR_DB 15.0           /* doubt only where the live music averages this far over the noise floor [dB] */
#define NEUTRAL_DB 1.0          /* a frame within this of a silent run's level range ... */
#define REGAIN_S 0.5            /* measurements in a row for this long end a hold with the search beside [s] */
#define PROBATION_BAD_S 0.2     /* bad ticks for this long in probation (after a resume) send the place to the search [s] */
#define ONSET_DB 1.5            /* resume: the music began at the first frame of the run this far over the silence [dB] */
#define ONSET_SIGMAS 4.0        /* ... or this many of the silence's frame-to-frame deviations */
#define RESUME_MIN_WINDOW_S 0.32  /* fewest live frames for a tracking measurement after a resume [s] */
#define SPARSE_EVIDENCE 3       /* silent frames where music is expected ... */
#define SPARSE_SPAN_S 1.0       /* ... spread over a hiss-flat stretch this long also mean a pause [s] */
#define STILL_S 0.5             /* the live level this long within STEADY_RANGE_DB of a line (hiss, the knob
                                 * turning or not) ... [s] */
#define MOVING_DB 12.0          /* ... where the music expected strays this much from one is a pause [dB] */
#define STILL_LOOK_S 2.0        /* ... looked for over this long since a fall of the level ... [s] */
#define DROP_DB 10.0            /* ... by this much ... [dB] */
#define DROP_FRAMES 3           /* ... within this many frames (a room's tail) [1] */
#define STILL_MAX 512           /* most frames in STILL_LOOK_S [1] */
#define RESUME_SIGMAS 5.0       /* a frame this many of the silence's deviations over it is music again */
#define NEAR_S 5.0              /* the near search gives up this long after the restart [s] */
#define NEAR_SEP 4              /* a rival peak of the near search lies at least this far away [ticks] */
#define PATIENT_AFTER_S 5.0     /* after this much first search, the verification window grows ... [s] */
#define LONG_VERIFY_S 10.0      /* ... up to this: alike, slow music needs more audio [s] */
#define STOP_TIE_DB2 1.0        /* splits whose misfit differs less than this tie [dB^2] */
#define STOP_SPAN 256           /* splits the stop fit weighs, at most [ticks] */
#define MAX_RATE_FIX 0.03       /* a verification corrects the rate by at most this [stored ticks per tick] */
#define ALT_REACH 10            /* the never-stopped place is taken only this close to its line [ticks] */
#define LONG_HOLD_S 1.0         /* a hold this long without a measurement leaves the place unproven [s] ... */
#define PROOF_CONF 0.5          /* ... until the confidence is back to this [1] */
#define SEARCH_GAP_S 1.0        /* steady hiss this long while searching: the tape stood still [s] */
#define LEADER_S 0.2            /* a cue's leader: steady frames before the music [s] ... */
#define LEADER_WAIT_S 0.5       /* ... none by then: the music played from the first frame [s] */
#define LEADER_CHECKS 20        /* ... or music, if it fits the cue at a multiple of LEADER_WAIT_S, up to this [1] */
#define NOTE_DB 6.0             /* ... or a frame this strong in onsets (a note's attack) [dB] */
#define RISE_DB 6.0             /* the music starts: a frame this far over the leader [dB] ... */
#define RISE_START_DB 1.0       /* ... its rise began at the first frame this far over it [dB] */
#define CUE_FITS 32             /* joint fits of rate and offset on lines through the cue, after ... */
#define REF_PERIOD 0.020        /* the tick the per-tick smoothing constants were set at [s] */
#define FIT_MIN_S 0.32          /* a line fit needs at least this much music [s] */
#define RESUME_LOOK_S 0.5       /* a pause expects the music of this long after the stop [s] */
#define ONSET_BACK_S 1.0        /* a resume looks this far back for the rise [s] */
#define GAP_AHEAD_S 1.0         /* ... and up to this far on, unheard in a gap of the music [s] */
#define CLEAR_WINDOW_S 1.0      /* clear music: the live level over this long (half of it heard) [s] */
static const double CUE_FIT_AT_S[CUE_FITS] = {      /* ... this much music [s]: from FIT_MIN_S every 0.1 s */
    0.32, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.1, 1.2, 1.3, 1.4,   /* while the rate is open, */
    1.5, 1.6, 1.7, 1.8, 1.9, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0,    /* then every 0.5 s */
    5.5, 6.0, 6.5, 7.0, 7.5, 8.0, 8.5, 9.0};
#define CUE_REFUTE_S 2.0        /* no fit from this much music on refutes the cue [s] */
#define CUE_RATE_SPAN 0.07      /* rates 1 +- this [stored ticks per tick] ... */
#define CUE_RATE_STEP 0.005     /* ... in these steps */
#define CUE_LAGS 5              /* offsets from the line through the cue, either way [ticks] */
#define MODEL_HISS_SIGMA 1.0     /* model: a stop's hiss wobbles at least this much, 1 sigma [dB] */
#define MODEL_MUSIC_SPAN 60.0    /* model: music after a stop lies up to this far over its hiss [dB] */
#define MODEL_IDLE 8             /* model: the search's pace, 1/this, while the place is clear [1] */
#define MODEL_USUAL_S 10.0       /* model: how well the music fits its place, averaged over this long [s] */
#define MODEL_CUE_DOUBT 0.01     /* model: P(a cue, or a place just taken over, is wrong), a priori [1] */
#define MODEL_ASTRAY_VAR_P 4.0   /* model: the position's variance when the tracker went astray [tick^2] */
#define MODEL_ASTRAY_VAR_R 1e-4  /* ... and the rate's [1] */
#define MODEL_ELSE_Z 0.3         /* model: somewhere else fits this much under the usual fit here, in Fisher z: music fits
                                  * some passages less well than others, a jump worse still [1] */
#define MODEL_LOCK_RATE_VAR 9e-4 /* model: the rate's variance when a candidate is taken: a lock on a short
                                  * window knows the rate to a few % [1] */
#define CUE_LOCK 0.8            /* a fit this good, and sharp, locks the cue [1] ... */
#define CUE_PRIOR 0.5           /* ... if it leads every other place by this times a search lock's lead,
                                 * over the square root of the bands; with bands, if no other place
                                 * leads it by that much (cue_lead, cue_fit) [1] */

typedef struct {
    double p;                   /* position at step t [stored ticks] */
    double score;               /* its coarse score [1] */
    uint64_t t;                 /* step it was found */
    int used;
    double rho;                 /* model: its score on the window of the place belief [1], NAN: none */
} sweep_peak;

typedef struct {
    double p, r;                /* position now [stored ticks], rate [stored ticks per tick] */
    double coarse;              /* coarse score of its last sweep [1] */
    double fine;                /* last verification score [1], NAN if none */
    double kappa;               /* sharpness of its correlation peak, the flatter half [1/tick^2] */
    size_t frames;              /* live frames behind its last verification [ticks] */
    int confirmed;              /* consecutive verifications with a small correction */
    int used;
    int track;                  /* the tracker's own hypothesis */
    uint64_t since;             /* first step whose frame is consistent with it */
    uint64_t checked;           /* step of its last verification */
    uint64_t sweep;             /* sweep that last scored it */
    double rho;                 /* model: its score on the followed place's window [1], NAN: none */
    double belief;              /* model: its log weight against the followed place's [1], NAN: none yet */
} cand;

/* A feature the correlations run on: `bands` values per frame (one for
 * the loudness and the onset features), live and stored, and the stored
 * side's block averages for the search. */
typedef struct {
    size_t bands;               /* values per frame; 0: the show has none */
    double *ring;               /* live feature: ring[(step & hmask) * bands + b], NAN when missing */
    double *buf;                /* stored: band b's frame j at buf[b * nfb + pad + j], j in [-pad, n + pad) */
    double *q1, *q2;            /* prefix sums of each band (mar_corr_stored) */
    double *blk;                /* coarse blocks: band b's block m at blk[b * ncb + cpad + m] */
    double *c1, *c2;            /* their prefix sums, (ncb + 1) per band */
    double lvl[MAR_CORR_MAX_BANDS];     /* running peak level of each live band [dB] */
    int lvl_started;
} channel;

/* The options in ticks of opt.tick_period, as the step uses them (made at create). */
typedef struct {
    double latency;             /* [ticks] */
    size_t window, min_window, verify_window, lock_window, paper_window;  /* [ticks] */
    size_t search_block;        /* [ticks] */
    size_t search_window;       /* [search blocks] */
    double rate_step;           /* the search's grid step, widened to at most MAX_RATES rates [1] */
    double hold_after, search_after, lost_after, quiet_lost_after, pause_after;  /* [ticks] */
    double meas_noise;          /* [stored ticks] */
    double rate_var;            /* the rate's variance growth per tick [1] */
    /* the algorithm's own times and rates (the #defines above) per tick */
    uint64_t floor_block, sparse_span, still_after, still_look, regain, probation_bad, near, patient_after, long_verify,
        long_hold, search_gap, leader, leader_wait;     /* [ticks] */
    size_t resume_min_window, fit_min, resume_look, onset_back, gap_ahead, clear_window;  /* [ticks] */
    size_t cue_fit_at[CUE_FITS];  /* [ticks] */
    int cue_refute_fit;           /* the first fit (index) that may refute the cue when nothing fits */
    double level_release, gain_step;    /* [dB per tick] */
    double gain_prior;          /* [ticks] */
    double gain_alpha, gain_slow_alpha, pause_alpha, h_fast, h_slow;   /* smoothing per tick [1] */
    /* the model's */
    double stop_hazard, start_hazard;  /* P(the deck stops, starts) per tick [1] */
    double log_share;           /* log P(the tape jumps to a given place) per tick [1] */
    double evidence_per_frame;  /* independent values per frame and band [1] */
    double usual;               /* MODEL_USUAL_S [ticks] */
} tick_options;

struct mar_follow {
    mar_follow_options opt;     /* as given [s] */
    tick_options tk;            /* ... in ticks */
    size_t n;                   /* stored frames */
    long pad;                   /* padding frames before and after the stored feature */
    size_t nfb;                 /* stored frames per band with the padding: n + 2 pad */
    double *sdb_buf, *sdb;      /* stored level [dB], sdb[-pad .. n + pad) */
    int onsets;                 /* 1: made with onsets; the tracker measures the onset feature's lag as well */
    double s_level;             /* loud reference of the stored music [dB] */
    channel level;              /* the loudness's level feature (one band) */
    channel onset;              /* the onset feature: level + onset_weight * onset strength (one band) */
    channel band;               /* the band levels' features (bands: 0 when the show has none) */
    channel *main;              /* what the correlations use: band when the show and the newest frame
                                 * have bands (smooth mode), else level */

    size_t D, nc, ncb;          /* coarse block [ticks], coarse blocks, with the padding */
    long cpad;

    /* live history, a ring indexed by step (the features' rings too) */
    size_t hcap, hmask;
    double *ldb;                /* level [dB], NAN when missing */
    double *lpos;               /* position estimate at that step [stored ticks] */
    double nf;                  /* noise floor estimate [dB]: quietest live frame of the last 20 s */
    double floor_min[FLOOR_BLOCKS];  /* per block, its quietest frame [dB] */
    double tape_hiss;           /* the tape's hiss, its quietest frame heard while PAUSED, live minus
                                 * gain [stored dB]; NAN: not heard yet */
    uint64_t floor_frames;      /* frames counted into the blocks */

    uint64_t t;                 /* steps done */
    uint64_t seg_start;         /* first step of the current continuous stretch of tape */
    uint64_t search_from;       /* first step the search may use */

    /* tracker */
    int state;
    mar_kf kf;                  /* position [stored ticks] and rate [stored ticks per tick], their covariance */
    double conf;
    int ever;                   /* a position is known (lock, reset or cue) */
    int located;                /* ... and proven or given (lock, reset), not only cued: the first
                                 * search's patience is for a follower that was never located */
    uint64_t last_good;         /* step of the last accepted measurement */
    uint64_t bad_since, quiet_since;  /* unclear / quiet steps since last_good */
    double gain;                /* live minus stored level [dB] */
    double gain_slow;           /* ... followed slowly: the knob turns while the two differ [dB] */
    int have_gain;
    double gain_heard;          /* loud frames the gain was fitted to since the last stop [frames] */
    uint64_t silent_run;
    uint64_t silent_start;      /* step of the first frame of the current silent run */
    double frozen;              /* position held in a pause [stored ticks] */
    uint64_t loud_run;          /* frames over the floor while paused */
    double resume_db;           /* a frame this far over the pause's level resumes [dB] */
    double pause_db;            /* the level of the silence in a pause [dB] */
    int measured;               /* a measurement was accepted since the last lock or resume */
    double silent_lo, silent_hi;  /* level range of the current silent run [dB] */
    double pause_dev;           /* the silence's mean frame-to-frame deviation in a pause [dB] */
    double h_slow, h_fast;      /* tracking peak heights: long-run, short-run average [1] */
    double h_var;               /* the heights' long-run variance about h_slow [1] */
    uint64_t h_low_since;       /* 1 + the step where the current run of low heights began; 0: none */
    int doubt;                  /* the tracking correlation collapsed in music: search beside, keep it going */
    int regaining;              /* the tracking went bad long enough to start the search beside: ... */
    uint64_t regain_ok;         /* ... not LOCKED again until this many measurements in a row fit, */
    uint64_t regain_bad;        /* ... and lost after this many bad ones in all [ticks] */
    int probation;              /* resumed from a pause: not LOCKED until the place is confirmed */
    uint64_t probation_ok;      /* accepted measurements since the resume */
    uint64_t pause_start;       /* step the pause was detected */
    uint64_t gap_run;           /* while searching: frames of steady hiss near the floor in a row, */
    double gap_lo, gap_hi;      /* ... their level range [dB] */
    int unproven;               /* held long without a measurement: not LOCKED until the confidence is back */

    /* near search: after a restart, the place is looked for around the resumed one */
    int near;                   /* running */
    double near_p, near_r;      /* centre of its reach now [stored ticks], its rate [stored ticks per tick] */
    uint64_t near_from;         /* first live step it uses (the restart) */
    uint64_t near_end;          /* step it gives up */
    double near_prev;           /* its last clear offset [ticks], NAN if none */
    int near_confirmed;         /* consecutive ticks it found the same offset */
    double alt_p;               /* the place now had the tape not stopped [stored ticks], NAN if none */
    double alt_prev;            /* its last clear offset [ticks], NAN if none */
    int alt_confirmed;          /* consecutive ticks it found the same offset */
    uint64_t stop_at;           /* the first step the pause holds to have been silent */

    /* search */
    int searching;
    cand pool[POOL];
    size_t n_rates;
    double rates[MAX_RATES];
    size_t sweep_o, sweep_k;
    uint64_t sweep_id, sweeps_done;
    sweep_peak peaks[PEAKS];    /* the best local maxima of the sweep under way ... */
    sweep_peak last_peaks[PEAKS];  /* ... and of the last complete one */
    double prev2_score, prev_score, here_score;   /* best coarse score at offsets o - 2, o - 1, o */
    double prev_rate, here_rate;
    size_t m_eff;               /* search window of this tick [coarse blocks] */
    size_t lc_cap;
    double *lc;                 /* live blocks, newest first: band b's at lc[b * lc_cap] */
    double *u;                  /* per rate and band: resampled live blocks, mean removed */
    double unorm[MAX_RATES];

    /* scratch for resampling */
    size_t scap;
    double *rs;                 /* resampled live values: band b's at rs[b * scap] */

    /* the cue (mar_follow_cue) */
    double cue_from;            /* the first audible stored frame at or after the cue [stored ticks] */
    int cue_pending;            /* cued, the music started, no fit has locked yet: never LOCKED by tracking */
    int cue_refine;             /* a fit locked the cue: later fits over more music may correct its line */
    uint64_t cue_onset;         /* step of the music's first frame */
    int cue_fits;               /* joint fits done */
    double cue_prev;            /* the last fit's line at its step if it was clear [stored ticks], else NaN */
    uint64_t cue_prev_t;        /* ... that step */
    uint64_t wait_frames;       /* WAITING: frames heard */
    uint64_t wait_start;        /* ... the step of the first */
    uint64_t leader;            /* ... frames of the steady leader (the run within STEADY_RANGE_DB) */
    double lead_lo, lead_hi;    /* ... its level range [dB] */
    uint64_t rise_step;         /* ... first frame of a rise over it, 0: none */

    /* mar_follow_tick: the clock between frames */
    mar_follow_out last;        /* the last step's answer */
    int64_t ticks_since_frame;  /* ticks since the last frame [ticks] */
    int64_t unstepped;          /* ticks since the last step [ticks] */

    /* the tape deck model (mode MAR_FOLLOW_MODEL, mar_follow_deck.h) */
    mar_deck_motion motion;
    uint64_t stop_run;          /* first step of the newest run of frames that favour a stop */
    uint64_t play_run;          /* ... that favour playing */
    double lead_belief, else_belief;    /* log weights of the followed place and of somewhere else [1] */
    uint64_t belief_t;          /* the step the place belief was last updated */
    int proven;                 /* the followed place has met a whole sweep's candidates (a cue has not) */
    double rho_usual;           /* how well the followed place has fitted, over the last MODEL_USUAL_S [1], NAN: not yet */
    int rescore;                /* the pool entry rescored next */

    mar_follow_counters c;
};

#define OPTION_INFO(name, type, def, lo, hi, unit, why) \
    {#name, MAR_FOLLOW_KIND_##type, offsetof(mar_follow_options, name), def, lo, hi, unit, why},
const mar_follow_option_info mar_follow_option_table[] = {MAR_FOLLOW_OPTIONS(OPTION_INFO)};
#undef OPTION_INFO
const size_t mar_follow_option_count = sizeof mar_follow_option_table / sizeof mar_follow_option_table[0];

void mar_follow_default_options(mar_follow_options *o)
{
    memset(o, 0, sizeof *o);
    o->tick_period = 0.020;
#define OPTION_DEFAULT(name, type, def, lo, hi, unit, why) o->name = def;
    MAR_FOLLOW_OPTIONS(OPTION_DEFAULT)
#undef OPTION_DEFAULT
}

/* A time [s] in ticks of period [s]; within 1e-9 of a whole tick it is
 * that tick (0.5 s / 0.02 s is 25, not 24.999...). */
static double ticks_of(double seconds, double period)
{
    double t = seconds / period, whole = nearbyint(t);
    return fabs(t - whole) < 1e-9 ? whole : t;
}

static size_t whole_ticks(double seconds, double period) { return (size_t)nearbyint(seconds / period); }

/* A smoothing constant set per REF_PERIOD, per tick of period [s] (the
 * same time constant). */
static double per_tick(double alpha, double period) { return -expm1(log1p(-alpha) * period / REF_PERIOD); }

/* The options in ranges (the table's), then in ticks and against each
 * other: 0, or -EINVAL and *problem says which and why. */
static int tick_options_of(const mar_follow_options *o, tick_options *tk, const char **problem)
{
    const double T = o->tick_period;
#define REFUSE(why)        \
    do {                   \
        *problem = why;    \
        return -EINVAL;    \
    } while (0)
    if (!(T >= 0.001 && T <= 1.0))
        REFUSE("tick_period is outside [0.001, 1] s");
#define OPTION_CHECK(name, type, def, lo, hi, unit, why) \
    if (!(o->name >= (type)(lo) && o->name <= (type)(hi))) \
        REFUSE(#name " is outside its range");
    MAR_FOLLOW_OPTIONS(OPTION_CHECK)
#undef OPTION_CHECK
    tk->latency = o->latency / T;
    tk->window = whole_ticks(o->window, T);
    tk->min_window = whole_ticks(o->min_window, T);
    tk->verify_window = whole_ticks(o->verify_window, T);
    tk->lock_window = whole_ticks(o->lock_window, T);
    tk->paper_window = whole_ticks(o->paper_window, T);
    tk->search_block = whole_ticks(o->search_block, T);
    tk->search_window = tk->search_block ? whole_ticks(o->search_window, T * (double)tk->search_block) : 0;
    tk->hold_after = ticks_of(o->hold_after, T);
    tk->search_after = ticks_of(o->search_after, T);
    tk->lost_after = ticks_of(o->lost_after, T);
    tk->quiet_lost_after = ticks_of(o->quiet_lost_after, T);
    tk->pause_after = fmax(1.0, ticks_of(o->pause_after, T));
    tk->meas_noise = o->meas_noise / T;
    tk->rate_var = o->rate_walk * T;
    tk->floor_block = whole_ticks(FLOOR_BLOCK_S, T);
    tk->sparse_span = whole_ticks(SPARSE_SPAN_S, T);
    tk->still_after = whole_ticks(STILL_S, T);
    tk->still_look = whole_ticks(STILL_LOOK_S, T);
    if (tk->still_look > STILL_MAX)
        tk->still_look = STILL_MAX;
    tk->regain = whole_ticks(REGAIN_S, T);
    tk->probation_bad = whole_ticks(PROBATION_BAD_S, T);
    tk->near = whole_ticks(NEAR_S, T);
    tk->patient_after = whole_ticks(PATIENT_AFTER_S, T);
    tk->long_verify = whole_ticks(LONG_VERIFY_S, T);
    tk->long_hold = whole_ticks(LONG_HOLD_S, T);
    tk->search_gap = whole_ticks(SEARCH_GAP_S, T);
    tk->leader = whole_ticks(LEADER_S, T);
    tk->leader_wait = whole_ticks(LEADER_WAIT_S, T);
    tk->resume_min_window = whole_ticks(RESUME_MIN_WINDOW_S, T);
    tk->fit_min = whole_ticks(FIT_MIN_S, T);
    tk->resume_look = whole_ticks(RESUME_LOOK_S, T);
    tk->onset_back = whole_ticks(ONSET_BACK_S, T);
    tk->gap_ahead = whole_ticks(GAP_AHEAD_S, T);
    tk->clear_window = whole_ticks(CLEAR_WINDOW_S, T);
    tk->cue_refute_fit = 0;
    for (int i = 0; i < CUE_FITS; i++) {
        tk->cue_fit_at[i] = whole_ticks(CUE_FIT_AT_S[i], T);
        if (CUE_FIT_AT_S[i] < CUE_REFUTE_S)
            tk->cue_refute_fit = i + 1;
    }
    tk->level_release = LEVEL_RELEASE * T;
    tk->gain_step = GAIN_STEP * T;
    tk->gain_prior = ticks_of(GAIN_PRIOR, T);
    tk->gain_alpha = per_tick(GAIN_ALPHA, T);
    tk->gain_slow_alpha = per_tick(GAIN_SLOW_ALPHA, T);
    tk->pause_alpha = per_tick(PAUSE_ALPHA, T);
    tk->h_fast = per_tick(H_FAST, T);
    tk->h_slow = per_tick(H_SLOW, T);
    tk->stop_hazard = T / o->stop_every;
    tk->start_hazard = fmin(1.0, T / o->stop_for);
    tk->log_share = log(fmin(1.0, T / o->jump_every));
    tk->evidence_per_frame = o->evidence_rate * T;
    tk->usual = MODEL_USUAL_S / T;
    /* at most MAX_RATES rates, whatever the rate range */
    tk->rate_step = fmax(o->rate_step, (o->rate_max - o->rate_min) / (MAX_RATES - 1) * 1.000001);
    if (tk->min_window < 4 || tk->paper_window < 4)
        REFUSE("min_window and paper_window must be at least 4 ticks");
    if (tk->window < tk->min_window || tk->window > 8192 || tk->verify_window < tk->min_window
        || tk->verify_window > 8192)
        REFUSE("window and verify_window must lie between min_window and 8192 ticks");
    if (tk->lock_window < tk->min_window || tk->lock_window > tk->verify_window)
        REFUSE("lock_window must lie between min_window and verify_window");
    if (tk->paper_window > 8192)
        REFUSE("paper_window must be at most 8192 ticks");
    if (tk->search_block < 1 || tk->search_block > 64)
        REFUSE("search_block must be 1 to 64 ticks");
    if (tk->search_window < MIN_SEARCH_BLOCKS || tk->search_window > 1024)
        REFUSE("search_window must be 12 to 1024 search blocks");
#undef REFUSE
    *problem = NULL;
    return 0;
}

int mar_follow_check_options(const mar_follow_options *opt, const char **problem)
{
    tick_options tk;
    return tick_options_of(opt, &tk, problem);
}

static double level_db(double x) { return 20.0 * log10(x + TINY); }

/* The feature of one frame: level clamped at a running peak minus range. */
static double feature(double *lvl, int *started, double db, double range_db, double release)
{
    if (!*started) {
        *lvl = db;
        *started = 1;
    }
    *lvl = fmax(db, *lvl - release);
    return fmax(db, *lvl - range_db);
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static size_t ring(const mar_follow *f, uint64_t step) { return (size_t)(step & f->hmask); }

/* Band b of the main feature's live frame of age i (0 = newest); NAN when missing. */
static double live_at(const mar_follow *f, size_t age, size_t b)
{
    return f->main->ring[ring(f, f->t - age) * f->main->bands + b];
}

/* Ages of live frames usable from step `since` on, at most cap. */
static size_t usable(const mar_follow *f, uint64_t since, size_t cap)
{
    uint64_t have = f->t + 1 - (since > f->t + 1 ? f->t + 1 : since);
    if (have > f->hcap)
        have = f->hcap;
    return have < cap ? (size_t)have : cap;
}

mar_follow *mar_follow_create(const mar_follow_options *opt, const double *stored, size_t n_stored,
                              int *status)
{
    const mar_follow_music music = {.loudness = stored, .n = n_stored};
    return mar_follow_create_music(opt, &music, status);
}

mar_follow *mar_follow_create_onsets(const mar_follow_options *opt, const double *stored,
                                     const double *onset, size_t n_stored, int *status)
{
    const mar_follow_music music = {.loudness = stored, .onset = onset, .n = n_stored};
    return mar_follow_create_music(opt, &music, status);
}

static int channel_alloc(channel *ch, size_t bands, const mar_follow *f)
{
    ch->bands = bands;
    if (!bands)
        return 1;
    ch->ring = malloc(f->hcap * bands * sizeof(double));
    ch->buf = malloc(f->nfb * bands * sizeof(double));
    ch->q1 = malloc((f->nfb + 1) * bands * sizeof(double));
    ch->q2 = malloc((f->nfb + 1) * bands * sizeof(double));
    ch->blk = malloc(f->ncb * bands * sizeof(double));
    ch->c1 = malloc((f->ncb + 1) * bands * sizeof(double));
    ch->c2 = malloc((f->ncb + 1) * bands * sizeof(double));
    if (ch->ring)
        for (size_t i = 0; i < f->hcap * bands; i++)
            ch->ring[i] = NAN;
    return ch->ring && ch->buf && ch->q1 && ch->q2 && ch->blk && ch->c1 && ch->c2;
}

static void channel_free(channel *ch)
{
    free(ch->ring);
    free(ch->buf);
    free(ch->q1);
    free(ch->q2);
    free(ch->blk);
    free(ch->c1);
    free(ch->c2);
}

/* Band b of a channel's stored feature from linear values x[i * stride]
 * (i < n): the same map as live frames, its peak level starting at the
 * loud reference (90th percentile) so that silence before the music reads
 * as the floor, as it will live; the padding is that floor. Returns the
 * loud reference [dB]; sorted: scratch of n. */
static double stored_feature(mar_follow *f, channel *ch, size_t b, const double *x, size_t stride,
                             double *sorted)
{
    double *v = ch->buf + b * f->nfb + f->pad;
    for (size_t i = 0; i < f->n; i++)
        sorted[i] = level_db(x[i * stride]);
    qsort(sorted, f->n, sizeof(double), cmp_double);
    double loud = sorted[(size_t)(0.9 * (double)(f->n - 1))];
    double lvl = loud;
    int started = 1;
    for (size_t i = 0; i < f->n; i++)
        v[i] = feature(&lvl, &started, level_db(x[i * stride]), f->opt.range_db, f->tk.level_release);
    for (long i = 1; i <= f->pad; i++)
        v[-i] = v[(long)f->n - 1 + i] = loud - f->opt.range_db;
    return loud;
}

/* A channel's prefix sums, coarse blocks and their prefix sums, from its stored feature. */
static void channel_sums(mar_follow *f, channel *ch)
{
    for (size_t b = 0; b < ch->bands; b++) {
        const double *v = ch->buf + b * f->nfb;
        double *q1 = ch->q1 + b * (f->nfb + 1), *q2 = ch->q2 + b * (f->nfb + 1);
        q1[0] = q2[0] = 0.0;
        for (size_t q = 0; q < f->nfb; q++) {
            q1[q + 1] = q1[q] + v[q];
            q2[q + 1] = q2[q] + v[q] * v[q];
        }
        double *blk = ch->blk + b * f->ncb + f->cpad;
        for (long m = -f->cpad; m < (long)f->nc + f->cpad; m++) {
            double sum = 0.0;
            for (size_t k = 0; k < f->D; k++)
                sum += v[f->pad + m * (long)f->D + (long)k];
            blk[m] = sum / (double)f->D;
        }
        double *c1 = ch->c1 + b * (f->ncb + 1), *c2 = ch->c2 + b * (f->ncb + 1);
        c1[0] = c2[0] = 0.0;
        for (size_t q = 0; q < f->ncb; q++) {
            c1[q + 1] = c1[q] + blk[(long)q - f->cpad];
            c2[q + 1] = c2[q] + blk[(long)q - f->cpad] * blk[(long)q - f->cpad];
        }
    }
}

static int valid_values(const double *x, size_t count)
{
    for (size_t i = 0; i < count; i++)
        if (!isfinite(x[i]) || x[i] < 0.0)
            return 0;
    return 1;
}

mar_follow *mar_follow_create_music(const mar_follow_options *opt, const mar_follow_music *music, int *status)
{
    *status = -EINVAL;
    tick_options tk;
    const char *problem;
    size_t n_stored = music ? music->n : 0, nb = music && music->bands ? music->n_bands : 0;
    if (!opt || !music || tick_options_of(opt, &tk, &problem) < 0 || !music->loudness || n_stored < 2
        || n_stored > ((size_t)1 << 28) || (music->bands && (nb < 1 || nb > MAR_FOLLOW_MAX_BANDS))
        || !valid_values(music->loudness, n_stored) || (music->onset && !valid_values(music->onset, n_stored))
        || (music->bands && !valid_values(music->bands, n_stored * nb)))
        return NULL;

    *status = -ENOMEM;
    mar_follow *f = calloc(1, sizeof *f);
    if (!f)
        return NULL;
    f->opt = *opt;
    f->tk = tk;
    f->n = n_stored;
    f->onsets = music->onset != NULL;
    size_t longest = tk.window > tk.verify_window ? tk.window : tk.verify_window;
    if (longest < tk.long_verify)
        longest = tk.long_verify;
    if (tk.paper_window > longest)
        longest = tk.paper_window;
    size_t search_span = (size_t)((double)(tk.search_window + 2) * (double)tk.search_block / opt->rate_min) + 2;
    if (search_span > longest)
        longest = search_span;
    if (tk.still_look + DROP_FRAMES > longest)
        longest = tk.still_look + DROP_FRAMES;             /* stands_still looks back this far */
    f->hcap = 64;
    while (f->hcap < longest + 64)
        f->hcap <<= 1;
    f->hmask = f->hcap - 1;
    f->pad = (long)((double)f->hcap * opt->rate_max) + 4 * MAX_LAGS + 8;
    f->D = tk.search_block;
    f->nc = (n_stored + f->D - 1) / f->D;
    f->cpad = (long)tk.search_window + 4;
    f->scap = (size_t)((double)f->hcap * opt->rate_max) + 8;
    f->nfb = n_stored + 2 * (size_t)f->pad;
    f->ncb = f->nc + 2 * (size_t)f->cpad;
    size_t most = nb > 1 ? nb : 1;                  /* values per frame of the widest channel */

    f->n_rates = (size_t)floor((opt->rate_max - opt->rate_min) / tk.rate_step + 1e-9) + 1;
    f->sdb_buf = malloc(f->nfb * sizeof(double));
    f->ldb = malloc(f->hcap * sizeof(double));
    f->lpos = malloc(f->hcap * sizeof(double));
    f->lc_cap = (size_t)ceil((double)tk.search_window / opt->rate_min) + 4;
    f->lc = malloc(f->lc_cap * most * sizeof(double));
    f->u = malloc(f->n_rates * most * tk.search_window * sizeof(double));
    f->rs = malloc(f->scap * most * sizeof(double));
    double *sorted = malloc(n_stored * sizeof(double));
    int ok = channel_alloc(&f->level, 1, f) & channel_alloc(&f->onset, 1, f) & channel_alloc(&f->band, nb, f);
    if (!ok || !f->sdb_buf || !f->ldb || !f->lpos || !f->lc || !f->u || !f->rs || !sorted) {
        free(sorted);
        mar_follow_destroy(f);
        return NULL;
    }
    f->sdb = f->sdb_buf + f->pad;
    f->main = &f->level;

    f->s_level = stored_feature(f, &f->level, 0, music->loudness, 1, sorted);
    for (size_t b = 0; b < nb; b++)
        stored_feature(f, &f->band, b, music->bands + b, nb, sorted);
    free(sorted);
    for (long i = -f->pad; i < (long)n_stored + f->pad; i++)
        f->sdb[i] = i >= 0 && i < (long)n_stored ? level_db(music->loudness[i]) : level_db(0.0);
    for (long i = -f->pad; i < (long)n_stored + f->pad; i++) {
        double rise = music->onset && i >= 0 && i < (long)n_stored ? music->onset[i] : 0.0;     /* [dB] */
        f->onset.buf[f->pad + i] = f->level.buf[f->pad + i] + opt->onset_weight * rise;
    }
    channel_sums(f, &f->level);
    channel_sums(f, &f->onset);
    channel_sums(f, &f->band);
    for (size_t k = 0; k < f->n_rates; k++)
        f->rates[k] = opt->rate_min + tk.rate_step * (double)k;

    for (size_t i = 0; i < f->hcap; i++)
        f->ldb[i] = NAN, f->lpos[i] = 0.0;
    f->nf = INFINITY;
    for (int b = 0; b < FLOOR_BLOCKS; b++)
        f->floor_min[b] = INFINITY;
    f->tape_hiss = NAN;
    mar_follow_reset(f, NAN);
    *status = 0;
    return f;
}

void mar_follow_destroy(mar_follow *f)
{
    if (!f)
        return;
    channel_free(&f->level);
    channel_free(&f->onset);
    channel_free(&f->band);
    free(f->sdb_buf);
    free(f->ldb);
    free(f->lpos);
    free(f->lc);
    free(f->u);
    free(f->rs);
    free(f);
}

/* The tracking heights start afresh at h [1], their spread from what a
 * usual fit shows. */
static void heights_afresh(mar_follow *f, double h)
{
    f->h_slow = f->h_fast = h;
    f->h_var = (DOUBT_DROP / DOUBT_SIGMAS) * (DOUBT_DROP / DOUBT_SIGMAS);
    f->h_low_since = 0;
}

/* How far the short-run height must fall under the long-run one to doubt
 * the place [1]: a steady fit is doubted sooner than one that wavers. */
static double doubt_drop(const mar_follow *f)
{
    return fmin(DOUBT_DROP, fmax(DOUBT_DROP_MIN, DOUBT_SIGMAS * sqrt(f->h_var)));
}

static void clear_pool(mar_follow *f)
{
    memset(f->pool, 0, sizeof f->pool);
}

/* from: the first step whose frame the search may use. */
static void start_search(mar_follow *f, uint64_t from)
{
    if (f->searching)
        return;
    f->searching = 1;
    f->search_from = from > f->seg_start ? from : f->seg_start;
    clear_pool(f);
    memset(f->peaks, 0, sizeof f->peaks);
    memset(f->last_peaks, 0, sizeof f->last_peaks);
    f->sweep_o = 1;
    f->sweep_k = 0;
    f->sweep_id++;
    f->sweeps_done = 0;
    f->prev_score = f->prev2_score = f->here_score = -2.0;
}

static void stop_search(mar_follow *f)
{
    f->searching = 0;
    clear_pool(f);
}

/* Model: a place is followed afresh (a reset, a cue's onset, a lock, a
 * take-over): it alone weighs, somewhere else at a jump's share, and the
 * deck plays. proven: the place needs no proof (mar_follow_deck.h). */
static void model_follow_afresh(mar_follow *f, int proven)
{
    f->lead_belief = 0.0;
    f->else_belief = f->tk.log_share;
    f->belief_t = f->t;
    f->proven = proven;
    mar_deck_motion_init(&f->motion, 0.0, f->tk.stop_hazard, f->tk.start_hazard);
}

void mar_follow_reset(mar_follow *f, double position)
{
    f->ticks_since_frame = f->unstepped = 0;
    f->cue_pending = f->cue_refine = 0;
    f->silent_run = f->loud_run = 0;
    f->bad_since = f->quiet_since = 0;
    f->last_good = f->t;
    f->seg_start = f->t + 1;          /* older frames belong to another stretch of tape */
    f->have_gain = 0;
    f->doubt = f->probation = f->near = f->regaining = f->unproven = 0;
    f->gap_run = 0;
    heights_afresh(f, 0.0);
    model_follow_afresh(f, isfinite(position));     /* a known start (a seek) is given */
    f->stop_run = f->play_run = f->t + 1;
    f->rho_usual = NAN;
    stop_search(f);
    if (isfinite(position)) {
        double last = (double)f->n;
        f->kf.p = position < 0.0 ? 0.0 : position > last ? last : position;
        f->kf.r = 1.0;
        f->ever = f->located = 1;
        f->state = MAR_FOLLOW_HOLDING;
        f->conf = 0.0;
        mar_kf_init(&f->kf, 1.0, 1e-4);
    } else {
        f->kf.p = 0.0;
        f->kf.r = 0.0;
        f->ever = f->located = 0;
        f->state = MAR_FOLLOW_SEARCHING;
        f->conf = 0.0;
        mar_kf_init(&f->kf, 1e6, 1e-2);
        start_search(f, f->seg_start);
    }
    f->last = (mar_follow_out){.position = f->kf.p, .rate = f->kf.r, .confidence = 0.0, .state = f->state};
}

void mar_follow_cue(mar_follow *f, double position)
{
    mar_follow_reset(f, position);
    if (!isfinite(position))
        return;
    size_t j = (size_t)f->kf.p;                /* the first audible stored frame from the cue on */
    while (j + 1 < f->n && f->sdb[j] < f->s_level - MUSIC_RANGE_DB)
        j++;
    f->cue_from = f->kf.p > (double)j ? f->kf.p : (double)j;
    f->state = MAR_FOLLOW_WAITING;
    f->located = 0;                         /* a cue is a claim, not yet a place */
    f->kf.r = 0.0;
    f->wait_frames = f->leader = f->rise_step = 0;
    f->last = (mar_follow_out){.position = f->kf.p, .rate = 0.0, .confidence = 0.0, .state = f->state};
}

/* --- correlation along a line ------------------------------------------ */

/* A channel's live history resampled along the line (p, r) onto whole
 * stored frames (mar_corr_resample) into f->rs, inside the padded piece
 * with room for the widest lags. */
static size_t resample_ch(mar_follow *f, const channel *ch, double p, double r, size_t ages, long *j0,
                          double *center)
{
    const mar_corr_history live = {ch->ring, f->hmask, f->t, ch->bands};
    return mar_corr_resample(&live, ages, p, r, -f->pad + MAX_LAGS + 1, (long)f->n + f->pad - MAX_LAGS - 2,
                             f->scap, f->rs, j0, center);
}

static size_t resample(mar_follow *f, double p, double r, size_t ages, long *j0, double *center)
{
    return resample_ch(f, f->main, p, r, ages, j0, center);
}

/* A channel's stored side, as the correlations take it. */
static mar_corr_stored stored_of(const mar_follow *f, const channel *ch)
{
    return (mar_corr_stored){ch->buf, ch->q1, ch->q2, f->nfb, ch->bands};
}

/* The correlation of f->rs[k0 .. k0 + len) (resampled from the same
 * channel) with its stored feature at frames j0 + k0 + d + k, for d =
 * -lags .. lags (mar_corr_lags). Returns the live spread [dB]. */
static double correlate_ch(const mar_follow *f, const channel *ch, size_t k0, size_t len, long j0, int lags,
                           double *rho)
{
    const mar_corr_stored stored = stored_of(f, ch);
    return mar_corr_lags(f->rs + k0, f->scap, len, &stored, j0 + (long)k0 + f->pad, lags, rho);
}

static double correlate(const mar_follow *f, size_t k0, size_t len, long j0, int lags, double *rho)
{
    return correlate_ch(f, f->main, k0, len, j0, lags, rho);
}

/* --- the search ---------------------------------------------------------- */

/* Live blocks of `coarse` frames of the main feature, newest first, and
 * for each rate of the grid and each band the blocks resampled to stored
 * block spacing, the band's mean removed. Sets f->m_eff (0: too little
 * live audio yet). */
static void prepare_search(mar_follow *f)
{
    const size_t D = f->D, nb = f->main->bands, W = f->tk.search_window;
    size_t ages = usable(f, f->search_from, f->hcap);
    size_t nblocks = ages / D;
    if (nblocks > f->lc_cap)
        nblocks = f->lc_cap;
    f->m_eff = 0;
    if (nblocks < 2)
        return;
    size_t valid_blocks = 0;
    for (size_t b = 0; b < nblocks; b++) {
        size_t cnt = 0;
        for (size_t k = 0; k < D; k++)
            cnt += !isnan(live_at(f, b * D + k, 0));
        for (size_t band = 0; band < nb; band++) {
            double sum = 0.0;
            for (size_t k = 0; k < D; k++) {
                double v = live_at(f, b * D + k, band);
                if (!isnan(v))
                    sum += v;
            }
            f->lc[band * f->lc_cap + b] = cnt ? sum / (double)cnt : NAN;
        }
        if (cnt)
            valid_blocks++;
    }
    /* blocks of the window in stored spacing: m in [0, m_eff) needs live block
     * (m + 0.5) / r - 0.5 < nblocks - 1 for the slowest rate */
    size_t m_eff = (size_t)floor(((double)nblocks - 0.5) * f->opt.rate_min - 0.5);
    if (m_eff > W)
        m_eff = W;
    if (m_eff < MIN_SEARCH_BLOCKS || valid_blocks < MIN_SEARCH_BLOCKS)
        return;
    double spread_sum = 0.0;
    for (size_t k = 0; k < f->n_rates; k++) {
        double r = f->rates[k], ss = 0.0;
        for (size_t band = 0; band < nb; band++) {
            const double *lc = f->lc + band * f->lc_cap;
            double *u = f->u + (k * nb + band) * W, sum = 0.0;
            size_t cnt = 0;
            for (size_t m = 0; m < m_eff; m++) {
                double a = ((double)m + 0.5) / r - 0.5;
                size_t i0 = (size_t)(a < 0.0 ? 0.0 : a);
                double fr = a - (double)i0;
                if (fr < 0.0)
                    fr = 0.0;
                double v0 = lc[i0], v1 = i0 + 1 < nblocks ? lc[i0 + 1] : v0;
                double v = isnan(v0) ? v1 : isnan(v1) ? v0 : v0 + fr * (v1 - v0);
                u[m] = v;
                if (!isnan(v))
                    sum += v, cnt++;
            }
            double mean = cnt ? sum / (double)cnt : 0.0;
            for (size_t m = 0; m < m_eff; m++) {
                u[m] = isnan(u[m]) ? 0.0 : u[m] - mean;
                ss += u[m] * u[m];
            }
        }
        f->unorm[k] = sqrt(ss);
        spread_sum += sqrt(ss / (double)(m_eff * nb));
    }
    if (spread_sum / (double)f->n_rates < f->opt.quiet_db)
        return;                                       /* too quiet or flat to search */
    f->m_eff = m_eff;
}

/* Coarse score of block offset o (now = stored position o * coarse) at
 * rate k: the joint correlation over the main feature's bands (each band
 * on its own, as mar_corr_lags, cost a real false lock: docs/music.md). */
static double coarse_score(const mar_follow *f, long o, size_t k)
{
    const size_t M = f->m_eff, nb = f->main->bands;
    double cov = 0.0, ss = 0.0;
    size_t qa = (size_t)(o - (long)M + f->cpad), qb = (size_t)(o + f->cpad);
    for (size_t band = 0; band < nb; band++) {
        const double *u = f->u + (k * nb + band) * f->tk.search_window;
        const double *s = f->main->blk + band * f->ncb + f->cpad + o - 1;   /* s[-m] is block o - 1 - m */
        double a0 = 0.0, a1 = 0.0;
        size_t m = 0;
        for (; m + 2 <= M; m += 2) {
            a0 += u[m] * s[-(long)m];
            a1 += u[m + 1] * s[-(long)m - 1];
        }
        for (; m < M; m++)
            a0 += u[m] * s[-(long)m];
        cov += a0 + a1;
        const double *c1 = f->main->c1 + band * (f->ncb + 1), *c2 = f->main->c2 + band * (f->ncb + 1);
        double s1 = c1[qb] - c1[qa], s2 = c2[qb] - c2[qa];
        ss += s2 - s1 * s1 / (double)M;
    }
    if (!(ss > 1e-9) || !(f->unorm[k] > 1e-9))
        return 0.0;
    return cov / (f->unorm[k] * sqrt(ss));
}

/* Fisher's z of a correlation: differences of z compare correlations fairly
 * near 1, where a small step in rho is a large step in unexplained variance. */
static double fisher(double rho)
{
    rho = rho > 0.999 ? 0.999 : rho < -0.999 ? -0.999 : rho;
    return atanh(rho);
}

/* For eviction: a verified entry counts its fine score plus a bonus (block
 * averages correlate higher than single frames, so coarse scores run high). */
static double cand_rank(const cand *e) { return isnan(e->fine) ? e->coarse : e->fine + VERIFIED_BONUS; }

/* A scored place: refresh the pool entry near it, or take a free place, or
 * replace the weakest entry (never the tracker's own) if better. The
 * tracker's own entry counts as near only within TRACK_SEP: a place a few
 * ticks beyond the tracking lags (a small jump, 0.1-0.5 s) is the search's
 * to verify, as the tracker cannot follow it and its entry is reset to
 * the tracker's position every tick. */
static void offer(mar_follow *f, double p, double r, double score)
{
    cand *slot = NULL, *weakest = NULL;
    for (int i = 0; i < POOL; i++) {
        cand *e = &f->pool[i];
        if (!e->used) {
            if (!slot)
                slot = e;
            continue;
        }
        if (fabs(e->p - p) < (e->track ? TRACK_SEP : DISTINCT)) {
            if (e->sweep != f->sweep_id || score > e->coarse) {   /* fresh score each sweep */
                e->sweep = f->sweep_id;
                e->coarse = score;
                if (!e->track && isnan(e->fine)) {                /* not verified yet: the better guess */
                    e->p = p;
                    e->r = r;
                }
            }
            return;
        }
        if (!e->track && (!weakest || cand_rank(e) < cand_rank(weakest)))
            weakest = e;
    }
    if (!slot) {
        if (!weakest || cand_rank(weakest) >= score)
            return;
        slot = weakest;
    }
    /* live ticks its window covered: frames before are not known to fit */
    uint64_t span = (uint64_t)((double)(f->m_eff * f->D) / r) + f->D;
    memset(slot, 0, sizeof *slot);
    slot->used = 1;
    slot->p = p;
    slot->r = r;
    slot->coarse = score;
    slot->fine = NAN;
    slot->rho = slot->belief = NAN;
    slot->sweep = f->sweep_id;
    slot->since = f->t + 1 > span ? f->t + 1 - span : 0;
    if (slot->since < f->search_from)
        slot->since = f->search_from;
    slot->checked = f->t;
}

/* A local maximum of the sweep at p (now) [stored ticks]: kept if among the
 * PEAKS best, one per place. The pool may have no room for it, but a lock
 * elsewhere must still beat it. */
static void note_peak(mar_follow *f, double p, double score)
{
    sweep_peak *slot = NULL;
    for (int i = 0; i < PEAKS; i++) {
        sweep_peak *k = &f->peaks[i];
        if (k->used && fabs(k->p + (double)(f->t - k->t) - p) < DISTINCT) {
            if (score > k->score)
                k->p = p, k->score = score, k->t = f->t, k->rho = NAN;
            return;
        }
        if (!slot || (slot->used && (!k->used || k->score < slot->score)))
            slot = k;                                 /* a free entry, else the weakest */
    }
    if (slot->used && slot->score >= score)
        return;
    slot->p = p, slot->score = score, slot->t = f->t, slot->used = 1, slot->rho = NAN;
}

/* Offset sweep_o - 1 is a local maximum of the sweep: into the pool (if it
 * has room) and among the sweep's best places. */
static void peak_at_prev(mar_follow *f)
{
    double p = (double)((f->sweep_o - 1) * f->D);
    offer(f, p, f->prev_rate, f->prev_score);
    note_peak(f, p, f->prev_score);
}

/* Score the next search_budget (offset, rate) pairs of the sweep. Per
 * offset the best rate counts; only local maxima over offsets are offered. */
static void sweep(mar_follow *f, size_t budget)
{
    while (budget > 0) {
        if (f->sweep_o > f->nc) {                     /* a sweep is complete */
            if (f->prev_score >= SEARCH_MIN_SCORE && f->prev_score > f->prev2_score)
                peak_at_prev(f);
            memcpy(f->last_peaks, f->peaks, sizeof f->peaks);
            memset(f->peaks, 0, sizeof f->peaks);
            f->sweeps_done++;
            f->sweep_id++;
            f->sweep_o = 1;
            f->sweep_k = 0;
            f->prev_score = f->prev2_score = f->here_score = -2.0;
        }
        long o = (long)f->sweep_o;
        double s = coarse_score(f, o, f->sweep_k);
        if (s > f->here_score)
            f->here_score = s, f->here_rate = f->rates[f->sweep_k];
        budget--;
        if (++f->sweep_k >= f->n_rates) {             /* offset o done: was o - 1 a peak? */
            if (f->prev_score >= SEARCH_MIN_SCORE && f->prev_score >= f->prev2_score
                && f->prev_score > f->here_score)
                peak_at_prev(f);
            f->prev2_score = f->prev_score;
            f->prev_score = f->here_score;
            f->prev_rate = f->here_rate;
            f->here_score = -2.0;
            f->sweep_k = 0;
            f->sweep_o++;
        }
    }
}

/* The correlation peaks of the older (0) and the newer (1) half of the
 * newest `ages` live frames along the line (p, r), at lags up to
 * VERIFY_LAGS: lag [ticks], height [1], curvature kappa [1/tick^2], edge
 * (no peak), and ctr, the live age (+ 0.5) at the half's middle [ticks],
 * on the level feature (onset 0) or the onset feature (onset 1). Returns 0
 * when there is too little audio for it (or no onsets in the window). */
typedef struct {
    double lag, height, kappa, ctr;
    int edge;
} half_peak;

static int half_peaks_ch(mar_follow *f, int onset, double p, double r, size_t ages, half_peak hp[2])
{
    long j0;
    double center;
    size_t m = ages >= f->tk.min_window ? resample_ch(f, onset ? &f->onset : f->main, p, r, ages, &j0, &center) : 0;
    if (m < f->tk.fit_min)
        return 0;
    size_t h = m / 2;
    double rho[2 * MAX_LAGS + 1];
    for (int half = 0; half < 2; half++) {
        size_t k0 = half ? h : 0, len = half ? m - h : h;
        if (onset)
            correlate_ch(f, &f->onset, k0, len, j0, VERIFY_LAGS, rho);
        else
            correlate(f, k0, len, j0, VERIFY_LAGS, rho);
        hp[half].lag = mar_corr_peak(rho, VERIFY_LAGS, &hp[half].height, &hp[half].kappa, &hp[half].edge);
        double jmid = (double)j0 + (double)k0 + 0.5 * (double)(len - 1);
        hp[half].ctr = (p - 0.5 - jmid) / r;
    }
    return 1;
}

static int half_peaks(mar_follow *f, double p, double r, size_t ages, half_peak hp[2])
{
    return half_peaks_ch(f, 0, p, r, ages, hp);
}

/* The corrections of a line from the peaks of its two halves: rate error
 * *er [stored ticks per tick] (the lags' drift between the halves' middles,
 * at most MAX_RATE_FIX), position error now *ep [ticks]. */
static void line_fix(const half_peak hp[2], double *ep, double *er)
{
    double r = (hp[1].lag - hp[0].lag) / (hp[0].ctr - hp[1].ctr);
    if (r > MAX_RATE_FIX)
        r = MAX_RATE_FIX;
    if (r < -MAX_RATE_FIX)
        r = -MAX_RATE_FIX;
    *er = r;
    *ep = hp[1].lag + r * hp[1].ctr;
}

/* The verification window now [ticks]: verify_window, growing once the
 * first search has gone on for PATIENT_AFTER_S, up to LONG_VERIFY_S.
 * (A search after a jump or a loss keeps verify_window: its first frames
 * may still be of the old place.) */
static size_t verify_cap(const mar_follow *f)
{
    uint64_t waited = !f->located && f->t > f->search_from ? f->t - f->search_from : 0;
    size_t cap = f->tk.verify_window, limit = cap > f->tk.long_verify ? cap : f->tk.long_verify;
    if (waited > f->tk.patient_after)
        cap += (size_t)(waited - f->tk.patient_after);
    return cap < limit ? cap : limit;
}

/* Full-resolution check of a pool entry: the lags of the older and the
 * newer half of its window correct its position and rate; their mean
 * correlation is its score. */
static void verify(mar_follow *f, cand *e)
{
    e->checked = f->t;
    size_t ages = usable(f, e->since, verify_cap(f));
    e->frames = ages;
    half_peak hp[2];
    if (!half_peaks(f, e->p, e->r, ages, hp)) {
        e->fine = NAN;
        return;
    }
    const half_peak older = hp[0], newer = hp[1];     /* older: the smaller stored indices */
    e->kappa = fmin(older.kappa, newer.kappa);
    if (newer.edge || newer.height < f->opt.track_threshold) {
        e->fine = fmin(older.height, newer.height);
        e->confirmed = 0;
        if (!newer.edge)
            e->p += newer.lag;
        return;
    }
    if (older.edge || older.height < f->opt.track_threshold) {
        /* the older half does not fit (the tape jumped, or the place is wrong):
         * keep only the newer frames from now on */
        e->p += newer.lag;
        e->since = f->t + 1 - (ages - ages / 2);
        e->fine = 0.5 * (older.height + newer.height);
        e->confirmed = 0;
        return;
    }
    double ep, er;
    line_fix(hp, &ep, &er);
    e->p += ep;
    e->r += er;
    if (e->r < f->opt.rate_min)
        e->r = f->opt.rate_min;
    if (e->r > f->opt.rate_max)
        e->r = f->opt.rate_max;
    e->fine = 0.5 * (older.height + newer.height);
    if (fabs(ep) < 1.0 && fabs(er) < 0.004)
        e->confirmed++;
    else
        e->confirmed = 0;
}

/* Merge entries that converged onto the same place (onto the tracker's
 * own entry: within TRACK_SEP, see offer). */
static void dedup(mar_follow *f)
{
    for (int i = 0; i < POOL; i++) {
        if (!f->pool[i].used)
            continue;
        for (int j = i + 1; j < POOL; j++) {
            cand *a = &f->pool[i], *b = &f->pool[j];
            if (!b->used || fabs(a->p - b->p) >= (a->track || b->track ? TRACK_SEP : 0.5 * DISTINCT))
                continue;
            int drop_b = a->track || (!b->track && cand_rank(a) >= cand_rank(b));
            cand *loser = drop_b ? b : a, *keeper = drop_b ? a : b;
            if (loser->coarse > keeper->coarse)
                keeper->coarse = loser->coarse;
            loser->used = 0;
            if (!a->used)
                break;
        }
    }
}

/* The entry to verify next: unverified ones by coarse score, then the
 * longest unchecked, favouring the better. */
static cand *next_to_verify(mar_follow *f)
{
    cand *best = NULL;
    double bp = -INFINITY;
    for (int i = 0; i < POOL; i++) {
        cand *e = &f->pool[i];
        if (!e->used || e->checked == f->t)
            continue;
        double pri = isnan(e->fine) ? 1.0 + e->coarse : e->fine + 0.01 * (double)(f->t - e->checked);
        if (pri > bp)
            bp = pri, best = e;
    }
    return best;
}

/* Score of the line (p, r) on the newest `ages` live frames, without
 * changing anything [1]: the mean peak height of the two halves, the lower
 * one if either half has no peak. (verify() differs: it takes the lower one
 * when the newer half has no peak or a low one, the mean when only the
 * older half fails, as that half may predate a jump.) */
static double score_on(mar_follow *f, double p, double r, size_t ages)
{
    half_peak hp[2];
    if (!half_peaks(f, p, r, ages, hp))
        return -1.0;
    return hp[0].edge || hp[1].edge ? fmin(hp[0].height, hp[1].height)
                                    : 0.5 * (hp[0].height + hp[1].height);
}

/* A correlation peak of height rho [1] and curvature kappa [1/tick^2] is
 * good and sharp enough to lock on. */
static int lockable_peak(const mar_follow *f, double rho, double kappa)
{
    return rho >= f->opt.lock_threshold && kappa >= KAPPA_LOCK_Z * (1.0 - rho * rho);
}

/* The lead in Fisher z a lock needs over any other place, from a window of
 * `frames` live frames: a short window proves less, so the margin grows as
 * 1/sqrt(frames) below verify_window. */
static double lock_lead(const mar_follow *f, size_t frames)
{
    return f->opt.lock_margin * sqrt((double)f->tk.verify_window / (double)frames);
}

/* The entry to lock on, or NULL: good enough, confirmed, clearly ahead of
 * every other place, after a whole sweep. */
static cand *lock_choice(mar_follow *f)
{
    if (f->sweeps_done < 1)
        return NULL;
    cand *best = NULL;
    for (int i = 0; i < POOL; i++) {
        cand *e = &f->pool[i];
        if (e->used && !isnan(e->fine) && (!best || e->fine > best->fine))
            best = e;
    }
    if (!best || !lockable_peak(f, best->fine, best->kappa) || best->confirmed < LOCK_CONFIRM
        || usable(f, best->since, f->tk.lock_window) < f->tk.lock_window)
        return NULL;
    double margin = lock_lead(f, best->frames);
    for (int i = 0; i < POOL; i++) {
        cand *e = &f->pool[i];
        if (!e->used || e == best || fabs(e->p - best->p) < DISTINCT)
            continue;
        if (isnan(e->fine) && e->coarse >= best->fine - COARSE_SLACK)
            return NULL;                              /* a rival not looked at closely yet */
    }
    /* the rivals' scores came from windows of their own lengths; a longer
     * window scores lower, so a rival (a twin of a repeated section) may
     * look beaten only because more audio was held against it. Before the
     * lock, each is scored again on the very frames that back this place. */
    size_t ages = usable(f, best->since, verify_cap(f));
    double zb = fisher(score_on(f, best->p, best->r, ages));
    for (int i = 0; i < POOL; i++) {
        cand *e = &f->pool[i];
        if (e->used && e != best && fabs(e->p - best->p) >= DISTINCT && !isnan(e->fine)
            && zb - fisher(score_on(f, e->p, e->r, ages)) < margin)
            return NULL;
    }
    /* and so is each of the last sweep's best places, at this place's rate
     * (the pool may have had no room for the right one) */
    for (int i = 0; i < PEAKS; i++) {
        const sweep_peak *k = &f->last_peaks[i];
        double p = k->p + best->r * (double)(f->t - k->t);
        if (k->used && fabs(p - best->p) >= DISTINCT
            && zb - fisher(score_on(f, p, best->r, ages)) < margin)
            return NULL;
    }
    return best;
}

/* --- one tick ----------------------------------------------------------- */

/* The noise floor: the quietest frame of the last FLOOR_BLOCKS blocks. A
 * long memory: in music the quietest moments are rare, and a floor that
 * crept up to the music would make ordinary quiet frames look like a pause. */
static void note_floor(mar_follow *f, double db)
{
    size_t b = (size_t)(f->floor_frames / f->tk.floor_block) % FLOOR_BLOCKS;
    if (f->floor_frames % f->tk.floor_block == 0)
        f->floor_min[b] = INFINITY;               /* a new block replaces the oldest */
    f->floor_min[b] = fmin(f->floor_min[b], db);
    f->floor_frames++;
    double nf = INFINITY;
    for (int k = 0; k < FLOOR_BLOCKS; k++)
        nf = fmin(nf, f->floor_min[k]);
    f->nf = nf;
}

/* The tape's hiss in stored terms (live minus gain) is its quietest frame
 * heard while PAUSED. Nothing on a tape is quieter than its hiss, so a
 * frame heard while following (the state of the last step) more than a
 * hiss's wobble (STEADY_RANGE_DB) under it shows the volume knob turned
 * down at least that much. The gain is measured on loud music only:
 * without this, a knob turned down in a quiet passage left the gain high,
 * the music expected over the floor, and its hiss read as a stop
 * (waltz/pauses@20261122 stood 19 s while the tape played; docs/music.md). */
static void hiss_shows_knob(mar_follow *f, double db)
{
    if (f->state == MAR_FOLLOW_PAUSED && f->have_gain)
        f->tape_hiss = fmin(f->tape_hiss, db - f->gain);       /* (NAN: the first reading) */
    if (!f->have_gain || isnan(f->tape_hiss)
        || (f->state != MAR_FOLLOW_LOCKED && f->state != MAR_FOLLOW_HOLDING))
        return;
    double under = db - (f->tape_hiss + f->gain);      /* [dB] */
    if (under < -STEADY_RANGE_DB)
        f->gain += under + STEADY_RANGE_DB;          /* (not move_gain: this frame is the new floor) */
}

/* A frame's values are usable: loudness, onset (NaN: none) and bands
 * finite and >= 0. */
static int valid_frame(const mar_follow_frame *fr)
{
    if (!isfinite(fr->loudness) || fr->loudness < 0.0 || !(isnan(fr->onset) || (isfinite(fr->onset) && fr->onset >= 0.0)))
        return 0;
    return fr->n_bands <= MAR_FOLLOW_MAX_BANDS && valid_values(fr->bands, fr->n_bands);
}

/* This step's live frame (NULL: none came) into the rings. The bands
 * count where the show has them, as many: then the correlations run on
 * them (smooth mode); a frame without (a one-band node) leaves a gap in
 * the band feature and the correlations run on the loudness. */
static void take_frame(mar_follow *f, const mar_follow_frame *fr, uint32_t *flags, int *have)
{
    size_t slot = ring(f, f->t);
    *have = 0;
    f->level.ring[slot] = f->onset.ring[slot] = NAN;
    for (size_t b = 0; b < f->band.bands; b++)
        f->band.ring[slot * f->band.bands + b] = NAN;
    f->ldb[slot] = NAN;
    if (!fr) {
        *flags |= MAR_FOLLOW_F_NO_FRAME;
        f->c.missing++;
        return;
    }
    if (!valid_frame(fr)) {
        *flags |= MAR_FOLLOW_F_BAD_INPUT | MAR_FOLLOW_F_NO_FRAME;
        f->c.bad_input++;
        return;
    }
    double db = level_db(fr->loudness);
    f->ldb[slot] = db;
    f->level.ring[slot] = feature(&f->level.lvl[0], &f->level.lvl_started, db, f->opt.range_db,
                                  f->tk.level_release);
    /* a frame without its onset (a source that has none) leaves a gap in the
     * onset feature; a window without onsets tracks on the loudness alone */
    f->onset.ring[slot] = f->level.ring[slot] + (f->onsets ? f->opt.onset_weight * fr->onset : 0.0);
    int bands = f->band.bands && fr->n_bands == f->band.bands && f->opt.mode != MAR_FOLLOW_PAPER;
    for (size_t b = 0; bands && b < f->band.bands; b++) {
        int started = f->band.lvl_started;
        f->band.ring[slot * f->band.bands + b] = feature(&f->band.lvl[b], &started, level_db(fr->bands[b]),
                                                         f->opt.range_db, f->tk.level_release);
    }
    f->band.lvl_started |= bands;
    f->main = bands ? &f->band : &f->level;
    hiss_shows_knob(f, db);
    note_floor(f, db);
    f->c.frames++;
    *have = 1;
}

static double stored_db_at(const mar_follow *f, double x)
{
    long j = (long)floor(x);
    if (j < -f->pad || j >= (long)f->n + f->pad)
        return level_db(0.0);
    return f->sdb[j];
}

/* A frame at db [dB] would widen the current silent run's level range past
 * what hiss does: it is sound. */
static int leaves_silent_range(const mar_follow *f, double db)
{
    return fmax(f->silent_hi, db) - fmin(f->silent_lo, db) > STEADY_RANGE_DB;
}

/* The volume knob is turning: the feature's clamp lags behind it, so the
 * tracking correlation may drop without the place being wrong. */
static int knob_turning(const mar_follow *f)
{
    return f->have_gain && fabs(f->gain - f->gain_slow) > TURNING_DB;
}

/* The volume moved by step [dB]: the gain, and the noise floor with it
 * (the hiss is on the tape, before the knob). */
static void move_gain(mar_follow *f, double step)
{
    f->gain += step;
    for (int b = 0; b < FLOOR_BLOCKS; b++)
        f->floor_min[b] += step;
    f->nf += step;
}

/* Music at music_db heard over hiss at hiss_db: the powers add [dB]. */
static double over_hiss_db(double music_db, double hiss_db)
{
    return 10.0 * log10(pow(10.0, 0.1 * music_db) + pow(10.0, 0.1 * hiss_db));
}

/* Least squares line through y[0 .. n) at x = 0 .. n - 1: the largest
 * and least residual from it [same unit as y]. */
static void line_residuals(const double *y, size_t n, double *lo, double *hi)
{
    double mx = 0.5 * (double)(n - 1), my = 0.0, sxy = 0.0, sxx = 0.0;
    for (size_t i = 0; i < n; i++)
        my += y[i];
    my /= (double)n;
    for (size_t i = 0; i < n; i++)
        sxy += ((double)i - mx) * (y[i] - my), sxx += ((double)i - mx) * ((double)i - mx);
    double slope = sxx > 0.0 ? sxy / sxx : 0.0;
    *lo = INFINITY, *hi = -INFINITY;
    for (size_t i = 0; i < n; i++) {
        double res = y[i] - my - slope * ((double)i - mx);
        *lo = fmin(*lo, res), *hi = fmax(*hi, res);
    }
}

/* The step of the latest fall of the live level by DROP_DB within
 * DROP_FRAMES frames, at most `back` steps ago, no earlier than `oldest`;
 * 0 if none. */
static uint64_t last_drop(const mar_follow *f, uint64_t back, uint64_t oldest)
{
    uint64_t from = f->t + 1 > back ? f->t + 1 - back : 0;
    if (from < oldest + DROP_FRAMES)
        from = oldest + DROP_FRAMES;
    for (uint64_t q = f->t; q >= from; q--) {
        double db = f->ldb[ring(f, q)], peak = -INFINITY;
        for (uint64_t k = 1; k <= DROP_FRAMES; k++)
            peak = fmax(peak, f->ldb[ring(f, q - k)]);           /* NaN (no frame) ignored */
        if (!isnan(db) && peak - db >= DROP_DB)
            return q;
    }
    return 0;
}

/* A stop that the level alone cannot show, the gain estimate lagging a
 * knob turned just before or during it (the hiss then stands where the
 * music is expected): since its latest fall (the tape halting), for at
 * least STILL_S, the live level lies within STEADY_RANGE_DB of a line (hiss,
 * under a knob that may be turning) and steps less than STEADY_DB a frame,
 * while the stored music along the line, heard over the tape's hiss
 * (powers added), strays MOVING_DB from a line of its own. Hiss stands
 * still; music does not where it moves; and sustained music (a pad, a
 * room's tail) does not fall onto a flat level. The knob moves hiss and
 * music alike, so no gain is needed beyond the tape's hiss in stored terms
 * (floor minus gain, which move together). On a stop the frames since
 * the fall are the silent run that dates it, and the hiss sets the gain. */
static int stands_still(mar_follow *f)
{
    uint64_t drop = last_drop(f, f->tk.still_look, f->seg_start);
    if (!drop || f->t + 1 - drop < f->tk.still_after)
        return 0;
    size_t n = (size_t)(f->t + 1 - drop);
    double live[STILL_MAX], music[STILL_MAX], hiss = f->nf - f->gain;    /* [dB] */
    for (size_t i = 0; i < n; i++) {
        uint64_t q = drop + i;
        live[i] = f->ldb[ring(f, q)];
        if (isnan(live[i]) || (i && fabs(live[i] - live[i - 1]) > STEADY_DB))
            return 0;
        double p = q == f->t ? f->kf.p : f->lpos[ring(f, q)];
        music[i] = over_hiss_db(stored_db_at(f, p - 0.5 * f->kf.r - 0.5), hiss);
    }
    double lo, hi, mlo, mhi;
    line_residuals(live, n, &lo, &hi);
    if (hi - lo > STEADY_RANGE_DB)
        return 0;
    line_residuals(music, n, &mlo, &mhi);
    if (mhi - mlo < MOVING_DB)
        return 0;
    f->silent_run = n;
    f->silent_start = drop;
    f->silent_lo = f->silent_hi = live[n - 1];
    for (size_t i = 0; i < n; i++)
        f->silent_lo = fmin(f->silent_lo, live[i]), f->silent_hi = fmax(f->silent_hi, live[i]);
    /* the hiss heard alone shows the knob: the gain is the hiss's quietest
     * frame now (as the floor is the quietest frame heard) over the tape's hiss */
    double step = live[n - 1] - 0.5 * (hi - lo) - hiss - f->gain;        /* [dB] */
    move_gain(f, step);
    f->gain_slow += step;                            /* a reading, not a turn */
    return 1;
}

/* Pause detection while following; returns 1 when the recorder stopped.
 * Evidence only where the stored music says the live frame should stand
 * clearly over the noise floor; there a frame is "low" if far below what
 * is expected and "silent" if also near the floor. */
static int detect_pause(mar_follow *f, int have)
{
    if (!have || !f->have_gain || !f->measured)
        return 0;
    if (stands_still(f))
        return 1;                                     /* evidence even in doubt: music moves anywhere near */
    if (f->doubt && !knob_turning(f))
        return 0;                                     /* only when the position is trusted */
    double db = f->ldb[ring(f, f->t)];
    /* the stored frame this live frame should show: centre of the frame */
    double stored = stored_db_at(f, f->kf.p - 0.5 * f->kf.r - 0.5);
    double expected = stored + f->gain;
    double margin = expected - f->nf;                 /* [dB] over the floor */
    if (margin < AUDIBLE_DB || stored < f->s_level - MUSIC_RANGE_DB) {
        /* the music is quiet here: no evidence, but a frame that leaves the
         * silence's level range shows there is sound (music), not hiss */
        if (f->silent_run > 0 && leaves_silent_range(f, db))
            f->silent_run = 0;
        return 0;
    }
    int low = db < expected - fmin(LOW_DB, 0.5 * margin);
    if (!low && f->silent_run > 0 && db >= f->silent_lo - NEUTRAL_DB && db <= f->silent_hi + NEUTRAL_DB
        && expected < db + LOW_DB)
        return 0;                                     /* as quiet as the silence so far, and the music
                                                       * expected here would hardly stand over it
                                                       * (between drum hits): no evidence */
    if (low) {
        /* silent: near the floor and steady (hiss), not a gap between notes */
        double prev = f->ldb[ring(f, f->t - 1)];
        int steady = !isnan(prev) && fabs(db - prev) <= STEADY_DB;
        int deep = db < f->nf + fmin(NEAR_FLOOR_DB, 0.5 * margin) || db < expected - DEEP_DB;
        if (deep && steady) {
            /* hiss stays within a few dB; a quiet passage of music moves more */
            if (f->silent_run == 0 || leaves_silent_range(f, db)) {
                f->silent_run = 0;
                f->silent_lo = f->silent_hi = db;
                f->silent_start = f->t;
            }
            f->silent_lo = fmin(f->silent_lo, db);
            f->silent_hi = fmax(f->silent_hi, db);
            f->silent_run++;
        } else if (!(steady && f->silent_run > 0 && db >= f->silent_lo - NEUTRAL_DB
                     && db <= f->silent_hi + NEUTRAL_DB)) {
            f->silent_run = 0;                        /* (as quiet as the silence so far, where the
                                                       * music would stand only a little over it:
                                                       * no evidence) */
        }
    } else {
        f->silent_run = 0;
    }
    /* in a quiet passage evidence is sparse: a few silent frames where music
     * should be heard, and nothing but hiss in between for a second, will do */
    return (double)f->silent_run >= f->tk.pause_after
        || (f->silent_run >= SPARSE_EVIDENCE && f->t - f->silent_start >= f->tk.sparse_span);
}

/* Live minus stored level [dB] on the line (p, r), over loud stored frames:
 * from the last `ages` frames when starting, then smoothed frame by frame.
 * Returns the number of loud frames it heard. */
static size_t update_gain(mar_follow *f, double p, double r, size_t ages)
{
    ages = usable(f, f->seg_start, ages);
    double sum = 0.0;
    size_t cnt = 0;
    for (size_t i = 0; i < ages; i++) {
        double db = f->ldb[ring(f, f->t - i)];
        double s = stored_db_at(f, p - r * ((double)i + 0.5) - 0.5);
        if (!isnan(db) && s >= f->s_level - LOUD_DB)
            sum += db - s, cnt++;
    }
    if (!cnt)
        return 0;
    if (!f->have_gain) {
        f->gain = f->gain_slow = sum / (double)cnt;
        f->have_gain = 1;
        f->gain_heard = (double)cnt;
    } else {
        /* a frame far below is a dropout or a pause, not the volume knob; and
         * the knob turns slowly: at most GAIN_STEP */
        double diff = sum / (double)cnt - f->gain;
        if (diff > -LOW_DB) {
            f->gain_heard += (double)cnt;
            double step = fmax(-f->tk.gain_step, fmin(f->tk.gain_step, f->tk.gain_alpha * diff));
            move_gain(f, step);
        }
        f->gain_slow += f->tk.gain_slow_alpha * (f->gain - f->gain_slow);
    }
    return cnt;
}

/* One lag measurement d [ticks], c ticks in the past, into the filter: its
 * variance from the peak's curvature, times `share` (2: one of two
 * measurements of the same frames). Returns 0 when the gate (3 sigma, and
 * at least a tick) turns it away. */
static int lag_update(mar_follow *f, double c, double d, double kappa, double share)
{
    double var = mar_kf_lag_var(&f->kf, c);                           /* [tick^2] */
    double k = kappa / KAPPA_REF;
    double R = share * f->tk.meas_noise * f->tk.meas_noise / (k < 1.0 ? (k > 0.01 ? k : 0.01) : 1.0);
    if (d * d > 9.0 * (var + R) + 1.0)
        return 0;
    mar_kf_update(&f->kf, c, d, R);
    return 1;
}

/* Smooth tracking measurement; returns 1 if used, sets *quiet. The lags
 * searched cover 3 sigma of the predicted measurement (3 ticks at least,
 * WIDE_LAGS at most): wide after a resume, narrow while following. */
static int track_smooth(mar_follow *f, int *quiet, uint32_t *flags)
{
    size_t ages = usable(f, f->seg_start, f->tk.window);
    /* right after a resume a short window corrects the restart point early
     * (the gate and the probation keep it from doing harm) */
    size_t min_window = f->probation && f->tk.resume_min_window < f->tk.min_window ? f->tk.resume_min_window
                                                                                   : f->tk.min_window;
    *quiet = 0;
    if (ages < min_window) {
        *quiet = 2;                                   /* too little audio yet: no evidence */
        return 0;
    }
    long j0;
    double c;
    size_t m = resample(f, f->kf.p, f->kf.r, ages, &j0, &c);
    if (m < min_window / 2) {
        *quiet = 2;
        return 0;
    }
    double var = mar_kf_lag_var(&f->kf, c);                           /* [tick^2] */
    double span = ceil(3.0 * sqrt(var > 0.0 ? var : 0.0));
    int lags = span < TRACK_LAGS ? TRACK_LAGS : span > WIDE_LAGS ? WIDE_LAGS : (int)span;
    double rho[2 * MAX_LAGS + 1], h, kappa;
    int edge;
    double spread = correlate(f, 0, m, j0, lags, rho);
    if (spread < f->opt.quiet_db) {
        *quiet = 1;
        return 0;
    }
    double d = mar_corr_peak(rho, lags, &h, &kappa, &edge);
    f->h_fast += f->tk.h_fast * (h - f->h_fast);
    /* where the heights began to fall: a doubt's search hears from there */
    if (h >= f->h_slow - 0.5 * doubt_drop(f))
        f->h_low_since = 0;
    else if (!f->h_low_since)
        f->h_low_since = f->t + 1;
    if (edge || h < f->opt.track_threshold || !(kappa > 0.0))
        return 0;
    /* With onsets, the onset feature's lag too: rises survive a room's
     * colouring, which gives each held chord its own gain. Its lag is the
     * lag where the onsets are, so it is measured there (its slope centre),
     * not at the window's centre: one strong onset off the centre would
     * read a rate error as a position error. The bands' lag stays at the
     * window's centre (they change all over it: their own slope centre
     * moved the bench by hundredths of a point), and the two measure the
     * same frames, so each counts half. The loudness alone carries the
     * room's gains into its lag (tests/test_follow.py, the reverberant
     * room: 3 of 8 decks held with both lags, 6 with the onset lag alone):
     * without bands the onset lag replaces it. */
    double d2 = NAN, kappa2 = 0.0, c2 = 0.0;
    if (f->onsets) {
        double rho2[2 * MAX_LAGS + 1], h2;
        int edge2;
        long j2;
        if (resample_ch(f, &f->onset, f->kf.p, f->kf.r, ages, &j2, &c2) == m) {    /* 0: no onsets in the window */
            correlate_ch(f, &f->onset, 0, m, j2, lags, rho2);
            double lag = mar_corr_peak(rho2, lags, &h2, &kappa2, &edge2);
            if (!edge2 && kappa2 > 0.0) {
                const mar_corr_stored st = stored_of(f, &f->onset);
                double k_at = mar_corr_slope_center(&st, j2 + f->pad + (long)floor(lag + 0.5), m);
                d2 = lag;
                c2 = (f->kf.p - 0.5 - ((double)j2 + k_at)) / f->kf.r;     /* its age + 0.5 [ticks] */
            }
        }
    }
    if (!isnan(d2) && f->main != &f->band)
        d = d2, kappa = kappa2, c = c2, d2 = NAN;
    double share = isnan(d2) ? 1.0 : 2.0;
    double p0 = f->kf.p, r0 = f->kf.r;
    int used = lag_update(f, c, d, kappa, share);
    if (!isnan(d2))         /* its lag from the line as the first update left it */
        used |= lag_update(f, c2, d2 - ((f->kf.p - p0) - c2 * (f->kf.r - r0)), kappa2, share);
    if (!used)
        return 0;
    /* the long run learns from the usual fit, not from a collapse */
    double dh = h - f->h_slow;
    if (dh >= -doubt_drop(f)) {
        f->h_slow += f->tk.h_slow * dh;
        f->h_var += f->tk.h_slow * (dh * dh - f->h_var);
    }
    double qual = (h - f->opt.track_threshold) / (1.0 - f->opt.track_threshold);
    f->conf += 0.05 * (qual - f->conf);
    *flags |= MAR_FOLLOW_F_MEASURED;
    return 1;
}

/* Paper tracking: this tick's stored sample is the next one (p + 1), or
 * doubled (p) or one skipped (p + 2), whichever lag of -1, 0, +1 correlates
 * best over the window; returns 1 if the correlation decided, sets *quiet
 * and *step (0, 1, 2). */
static int track_paper(mar_follow *f, int *quiet, int *step, uint32_t *flags)
{
    *quiet = 0;
    *step = 1;
    size_t ages = usable(f, f->seg_start, f->tk.paper_window);
    if (ages < 8)
        return 0;
    long j0;
    double c;
    size_t m = resample(f, f->kf.p + 1.0, 1.0, ages, &j0, &c);
    if (m < 8)
        return 0;
    double rho[3];
    double spread = correlate(f, 0, m, j0, 1, rho);
    if (spread < f->opt.quiet_db) {
        *quiet = 1;
        return 0;
    }
    int b = rho[0] > rho[1] && rho[0] >= rho[2] ? 0 : rho[2] > rho[1] ? 2 : 1;
    if (rho[b] < f->opt.track_threshold)
        return 0;
    *step = b;                                        /* lag -1: double, 0: go on, +1: skip */
    double qual = (rho[b] - f->opt.track_threshold) / (1.0 - f->opt.track_threshold);
    f->conf += 0.05 * (qual - f->conf);
    *flags |= MAR_FOLLOW_F_MEASURED;
    return 1;
}

/* A second opinion on the line a lock takes (smooth mode, with onsets):
 * the onset feature's two half windows measure the same position and rate
 * corrections as the loudness's did in verify(), with errors of their own
 * (a room moves the loudness peak of held chords, not their rises). Where
 * both halves have a clear peak, the line moves halfway to theirs: the mean
 * of two independent estimates. Only the line moves, not the choice of the
 * place, which stays with the loudness (the onset feature of hiss would
 * lock on pauses). */
static void second_opinion(mar_follow *f, size_t ages)
{
    half_peak hp[2];
    if (!half_peaks_ch(f, 1, f->kf.p, f->kf.r, ages, hp) || hp[0].edge || hp[1].edge
        || hp[0].height < f->opt.track_threshold || hp[1].height < f->opt.track_threshold)
        return;
    double ep, er;
    line_fix(hp, &ep, &er);
    f->kf.p += 0.5 * ep;
    f->kf.r = fmax(f->opt.rate_min, fmin(f->opt.rate_max, f->kf.r + 0.5 * er));
}

static void lock_on(mar_follow *f, const cand *e, uint32_t *flags)
{
    double old = f->kf.p;
    int was_following = f->ever && f->state != MAR_FOLLOW_SEARCHING;
    f->kf.p = e->p;
    f->kf.r = e->r;
    if (f->onsets && f->opt.mode != MAR_FOLLOW_PAPER)
        second_opinion(f, usable(f, e->since, e->frames));
    if (f->opt.mode == MAR_FOLLOW_PAPER)
        f->kf.p = floor(f->kf.p + 0.5), f->kf.r = 1.0;
    mar_kf_init(&f->kf, 0.25, 1e-5);
    f->seg_start = e->since;
    f->state = MAR_FOLLOW_LOCKED;
    f->ever = f->located = 1;
    f->last_good = f->t;
    f->bad_since = f->quiet_since = 0;
    f->silent_run = 0;
    f->conf = (e->fine - f->opt.track_threshold) / (1.0 - f->opt.track_threshold);
    f->measured = 0;
    f->doubt = f->probation = f->regaining = f->unproven = f->cue_pending = f->cue_refine = 0;
    heights_afresh(f, e->fine);
    /* a broadband level gives each section of the music its own gain (a
     * room's or speaker's colouring: 30.2 to 33.6 dB on the pop piece), and a
     * lock's window may hold a few frames of one section: the gain heard
     * before, from the music followed, weighs in as GAIN_PRIOR of it */
    double before = f->have_gain && was_following ? f->gain : NAN, heard = fmin(f->gain_heard, f->tk.gain_prior);
    f->have_gain = 0;
    size_t loud = update_gain(f, f->kf.p, f->kf.r, f->tk.verify_window);
    if (!isnan(before) && f->have_gain) {
        double w = (double)loud / ((double)loud + heard);
        f->gain = f->gain_slow = before + w * (f->gain - before);
    }
    if (!was_following || fabs(old - f->kf.p) > 2.0)
        *flags |= MAR_FOLLOW_F_JUMP;
    f->c.locks++;
    f->near = 0;
    stop_search(f);
}

static double line_fit(mar_follow *f, size_t ages, double *best_r, double *best_d, double *best_kappa);

/* WAITING, `heard` frames since the first: is it time to ask whether the
 * music played from the first frame? At the cue's fit times before
 * LEADER_WAIT_S (music from the first frame, before a leader could form);
 * once a steady start was taken for a leader, every LEADER_WAIT_S up to
 * LEADER_CHECKS of them (the leader may be the music itself, a held chord). */
static int first_frame_fit_due(const mar_follow *f, uint64_t heard)
{
    if (heard < f->tk.leader_wait) {
        for (int i = 0; i < CUE_FITS; i++)
            if (f->tk.cue_fit_at[i] == heard)
                return 1;
        return 0;
    }
    return f->leader >= f->tk.leader && heard % f->tk.leader_wait == 0
        && heard <= LEADER_CHECKS * f->tk.leader_wait;
}

/* WAITING at the cue: has the music started? Before it, the input is a
 * steady leader (hiss, a room, digital silence: frames within
 * STEADY_RANGE_DB of each other); the music is a frame RISE_DB over it, and
 * it began at the first frame of that rise. No leader within LEADER_WAIT_S:
 * the music played from the first frame. Returns the onset's step
 * and 1 when the music started. */
static int music_started(mar_follow *f, int have, uint64_t *onset)
{
    if (!have)
        return 0;
    double db = f->ldb[ring(f, f->t)];
    uint64_t heard = ++f->wait_frames;
    if (heard == 1) {       /* the music may be playing elsewhere: the search listens from here */
        f->wait_start = f->cue_onset = f->t;      /* line_fit's music from the first frame */
        start_search(f, f->t);
    }
    /* a note: hiss and a room's noise read under about 1 dB of onsets, a
     * note's attack several times that */
    size_t slot = ring(f, f->t);
    double strength = f->onsets && f->opt.onset_weight > 0.0 ? (f->onset.ring[slot] - f->level.ring[slot]) / f->opt.onset_weight
                                                             : NAN;     /* NaN: the level decides */
    if (strength > NOTE_DB) {
        *onset = f->leader < f->tk.leader ? f->wait_start : f->rise_step ? f->rise_step : f->t;
        return 1;
    }
    if (first_frame_fit_due(f, heard)) {
        /* the music may have played from the first frame: it did, if the
         * frames since fit the stored music from the cue */
        double r, d, kappa;
        if (line_fit(f, (size_t)heard, &r, &d, &kappa) >= CUE_LOCK) {
            *onset = f->t + 1 - heard;
            return 1;
        }
    }
    if (f->leader < f->tk.leader) {                     /* the leader forming */
        double lo = f->leader ? fmin(f->lead_lo, db) : db, hi = f->leader ? fmax(f->lead_hi, db) : db;
        if (f->leader && hi - lo > STEADY_RANGE_DB)
            f->leader = 0, lo = hi = db;                /* not steady: start again here */
        f->leader++, f->lead_lo = lo, f->lead_hi = hi;
        if (f->leader < f->tk.leader && heard >= f->tk.leader_wait) {
            *onset = f->t + 1 - heard;                  /* no leader: music from the first frame */
            return 1;
        }
        return 0;
    }
    if (db <= f->lead_hi + RISE_START_DB) {             /* still the leader */
        f->rise_step = 0;
        if (db >= f->lead_hi - STEADY_RANGE_DB) {
            /* its range follows it down, and counts as STEADY_RANGE_DB wide
             * at least: a rise is measured from the top of the hiss's wobble */
            f->lead_lo = fmin(f->lead_lo, db);
            f->lead_hi = fmax(f->lead_hi, f->lead_lo + STEADY_RANGE_DB);
        }
        return 0;
    }
    if (!f->rise_step)
        f->rise_step = f->t;
    if (db < f->lead_hi + RISE_DB)
        return 0;
    *onset = f->rise_step;
    return 1;
}

/* The music started at step `onset`: play from the cue at rate 1. */
static void play_from_cue(mar_follow *f, uint64_t onset)
{
    f->cue_onset = f->seg_start = onset;
    f->kf.p = f->cue_from + (double)(f->t - onset) + 0.5;     /* its middle, on average */
    if (f->opt.mode == MAR_FOLLOW_PAPER)
        f->kf.p = floor(f->kf.p + 0.5);                           /* paper: whole stored samples */
    f->kf.r = 1.0;
    mar_kf_init(&f->kf, 1.0, 1e-3);
    f->state = MAR_FOLLOW_HOLDING;
    f->ever = 1;
    f->cue_pending = 1;
    f->cue_fits = 0;
    f->cue_prev = NAN;
    f->measured = 0;
    f->last_good = f->t;
    f->bad_since = f->quiet_since = 0;
    start_search(f, onset);         /* beside the cue; it may listen since the first frame (the
                                     * music may be elsewhere), its gap rule drops a leader */
}

/* The rate and offset of the line through the cue (the music's first
 * frame `ages` frames ago) that fit the live frames since best: returns its
 * correlation at the whole lag (as cue_rival scores), -1 if none fits, NaN
 * if the live frames are too flat to tell (no evidence either way). */
static double line_fit_ch(mar_follow *f, int onset, size_t ages, double *best_r, double *best_d,
                          double *best_kappa)
{
    const channel *ch = onset ? &f->onset : f->main;
    double best = NAN;                                          /* no evidence yet */
    *best_r = 1.0, *best_d = *best_kappa = 0.0;
    int steps = (int)(CUE_RATE_SPAN / CUE_RATE_STEP + 0.5);
    for (int i = -steps; i <= steps; i++) {
        double r = 1.0 + CUE_RATE_STEP * (double)i;
        double p = f->cue_from + r * ((double)ages - 0.5);     /* the line through the cue, now */
        long j0;
        double c, rho[2 * CUE_LAGS + 1], h, kappa;
        int edge;
        size_t m = resample_ch(f, ch, p, r, ages, &j0, &c);
        if (m < ages / 2)
            continue;
        if (correlate_ch(f, ch, 0, m, j0, CUE_LAGS, rho) < f->opt.quiet_db)
            continue;                                           /* flat: no evidence */
        double d = mar_corr_peak(rho, CUE_LAGS, &h, &kappa, &edge);
        if (isnan(best))
            best = -1.0;                                        /* evidence, no fit yet */
        if (!edge && h > best)
            best = rho[(int)lround(d) + CUE_LAGS], *best_r = r, *best_d = d, *best_kappa = kappa;
    }
    return best;
}

static double line_fit(mar_follow *f, size_t ages, double *best_r, double *best_d, double *best_kappa)
{
    return line_fit_ch(f, 0, ages, best_r, best_d, best_kappa);
}

/* With onsets: the line the onset feature fits best places the cue (rises
 * survive a room's colouring and sustained pads, as in the tracker); the
 * loudness's line stays where the onsets have no clear peak. */
static void onset_line(mar_follow *f, size_t ages, double *r, double *d)
{
    double r2, d2, kappa2;
    if (f->onsets && line_fit_ch(f, 1, ages, &r2, &d2, &kappa2) >= f->opt.track_threshold && kappa2 > 0.0)
        *r = r2, *d = d2;
}

/* The best correlation of the live frames resampled along a line (rs[0 ..
 * m), stored frames j0 ..) anywhere in the stored piece at least DISTINCT
 * from offset d [ticks] of that line: the cue's rival. Costs n m. */
static double cue_rival(const mar_follow *f, size_t m, long j0, double d)
{
    double rho[2 * MAX_LAGS + 1], best = -1.0;
    for (long c = -j0 + MAX_LAGS; c - MAX_LAGS <= (long)f->n - j0 - (long)m; c += 2 * MAX_LAGS + 1) {
        correlate(f, 0, m, j0 + c, MAX_LAGS, rho);
        for (int i = 0; i <= 2 * MAX_LAGS; i++) {
            long off = c + i - MAX_LAGS;
            if (fabs((double)off - d) > DISTINCT && rho[i] > best)
                best = rho[i];
        }
    }
    return best;
}

/* A cue's lead in Fisher z, from a window of `frames` live frames: a
 * share of a search lock's (the cue is the operator's word), shrinking as
 * 1/sqrt(bands) as lock_lead does with the frames (b bands hold b times
 * the independent values of one). cue_fit's lock asks a cue's line to
 * lead every other place by it on loudness alone, and lets another place
 * lead by it with bands; cue_refine asks a refit to lead the tracker's
 * line by it. */
static double cue_lead(const mar_follow *f, size_t frames)
{
    return CUE_PRIOR * lock_lead(f, frames) / sqrt((double)f->main->bands);
}

/* A fit of the cue's is due after `ages` frames of music: counts it, and
 * the fit times already gone with it (an onset placed in the past would
 * otherwise bring fits on consecutive ticks, nearly the same frames, which
 * would confirm each other). */
static int cue_fit_now(mar_follow *f, size_t ages)
{
    if (ages < f->tk.cue_fit_at[f->cue_fits])
        return 0;
    do
        f->cue_fits++;
    while (f->cue_fits < CUE_FITS && ages >= f->tk.cue_fit_at[f->cue_fits]);
    return 1;
}

/* Would the stored music of the last clear_window before stored frame p
 * be heard over a tape's hiss: is a frame of it loud (within LOUD_DB of
 * the piece's loud reference)? A quiet intro may lie under the hiss, and a
 * line that fails there is no evidence against the cue. */
static int loud_at(const mar_follow *f, double p)
{
    long end = (long)p, begin = end - (long)f->tk.clear_window;
    for (long j = begin > 0 ? begin : 0; j < end && j < (long)f->n; j++)
        if (f->sdb[j] >= f->s_level - LOUD_DB)
            return 1;
    return 0;
}

/* The cue is refuted: the search beside it, running since the onset
 * (since the first frame), decides; the position runs on. */
static void refute_cue(mar_follow *f)
{
    f->cue_pending = 0;
    f->state = MAR_FOLLOW_SEARCHING;
    f->doubt = f->probation = f->regaining = 0;
    start_search(f, f->cue_onset);
}

/* After CUE_FIT_AT frames of music: the rate and offset on lines through
 * the cue that fit the live music best. Two clear fits in a row on the
 * same line lock; a sharp fit places the line; a fit from 2 s of music on
 * that misses track_threshold where the stored music would be heard
 * (loud_at) refutes the cue (flat live music and a quiet intro are no
 * evidence): the whole-piece search takes over, the position running on. */
static void cue_fit(mar_follow *f, uint32_t *flags)
{
    size_t ages = (size_t)(f->t + 1 - f->cue_onset);
    if (!cue_fit_now(f, ages))
        return;
    double best_r, best_d, best_kappa;
    double best = line_fit(f, ages, &best_r, &best_d, &best_kappa);
    if (f->wait_start < f->cue_onset) {
        /* a quiet, steady start of the music may have been taken for the
         * leader: the line from the first frame heard competes */
        size_t early = (size_t)(f->t + 1 - f->wait_start);
        double r2, d2, kappa2, fit2 = line_fit(f, early, &r2, &d2, &kappa2);
        if (fit2 > best || (isnan(best) && fit2 >= f->opt.track_threshold)) {
            best = fit2, best_r = r2, best_d = d2, best_kappa = kappa2, ages = early;
            f->cue_onset = f->seg_start = f->wait_start;
        }
    }
    int sharp = lockable_peak(f, best, best_kappa);
    double rival = -1.0;
    if (best >= CUE_LOCK && sharp) {
        long j0;
        double c;
        size_t m = resample(f, f->cue_from + best_r * ((double)ages - 0.5), best_r, ages, &j0, &c);
        rival = m ? cue_rival(f, m, j0, best_d) : 1.0;
    }
    double lead = fisher(best) - fisher(rival);
    if (best >= f->opt.track_threshold)
        onset_line(f, ages, &best_r, &best_d);
    /* With bands a repeat of the music's opening fits about as well as the
     * top (on the synthesized pieces the first 0.3-0.5 s fit later bars at
     * 0.96-0.99), and a lead over it held those cues until the music parted
     * from its repeats (0.6-7 s): there the cue, the operator's word, locks
     * unless another place leads it by cue_lead. On loudness alone the lead
     * also guards the line: slow pads fit lines through the cue at several
     * rates, and a lock on one hands the tracker a wrong rate */
    double need = f->main->bands > 1 ? -cue_lead(f, ages) : cue_lead(f, ages);
    int clear = best >= CUE_LOCK && sharp && lead >= need;
    double line_now = f->cue_from + best_r * ((double)ages - 0.5) + best_d;     /* [stored ticks] */
    /* two clear fits in a row on the same line, as a search lock is confirmed */
    int confirmed = clear && fabs(line_now - (f->cue_prev + best_r * (double)(f->t - f->cue_prev_t))) <= 1.0;
    f->cue_prev = clear ? line_now : NAN;
    f->cue_prev_t = f->t;
    if (f->opt.mode == MAR_FOLLOW_PAPER)           /* paper: whole samples, one per tick */
        line_now = floor(line_now + 0.5), best_r = 1.0;
    if (confirmed) {
        f->kf.p = line_now;
        f->kf.r = best_r;
        double rate_sd = 1.0 / (double)ages;                    /* a tick over the fit [1] */
        mar_kf_init(&f->kf, 0.25, rate_sd * rate_sd);
        f->cue_pending = 0;
        f->cue_refine = f->opt.mode == MAR_FOLLOW_SMOOTH;
        f->located = f->measured = 1;
        f->state = MAR_FOLLOW_LOCKED;
        f->last_good = f->t;
        f->bad_since = 0;
        f->conf = (best - f->opt.track_threshold) / (1.0 - f->opt.track_threshold);
        heights_afresh(f, best);
        f->c.locks++;
        *flags |= MAR_FOLLOW_F_MEASURED;
    } else if (best >= f->opt.track_threshold && sharp) {
        /* a clear fit over all the music since the onset places the line
         * better than the tracker's first short windows (their rate runs
         * away in sustained music); the place stays unproven. A flat peak
         * (slow pads) leaves the rate open: the tracker keeps it */
        f->kf.p = line_now;
        f->kf.r = best_r;
        mar_kf_init(&f->kf, 1.0, 4.0 / ((double)ages * (double)ages));  /* a tick over the fit, twice [1] */
    } else if (f->cue_fits > f->tk.cue_refute_fit && best < f->opt.track_threshold   /* NaN: flat */
               && loud_at(f, f->cue_from + (double)ages)) {
        refute_cue(f);
    }
}

/* The correlation of the live frames of the last `ages` with the stored
 * feature (loudness, or onsets when ch is 1) exactly on the line (p, r):
 * lag 0 of the resampled window; -1 when too few frames lie on it. */
static double line_score(mar_follow *f, int ch, double p, double r, size_t ages)
{
    long j0;
    double c, rho[1];
    const channel *c_ch = ch ? &f->onset : f->main;
    size_t m = resample_ch(f, c_ch, p, r, ages, &j0, &c);
    if (m < ages / 2)
        return -1.0;
    correlate_ch(f, c_ch, 0, m, j0, 0, rho);
    return rho[0];
}

/* After a cue lock, until the music since the onset fills the tracker's
 * window: the line through the cue fitted to all of it (at the cue's fit
 * times), against the tracker's own line on the very same frames. The
 * lock came from 0.5-1 s of music, where a line a few percent off in rate
 * that crosses the right one in the middle fits about as well; the
 * tracker's windows, all centred near that crossing, cannot see the
 * difference (their lag is e_p - c e_r, near 0), and its filter, fed the
 * same frames every tick, grows sure of the line. A fit over all the
 * music since is one estimate from more of it: where it correlates better
 * than the tracker's line by cue_lead, and lies more than
 * a tick from it somewhere over the fit (less is within what either line
 * can tell: the fit's rate is on a grid, its peak wanders by some tenths
 * of a tick), the tracker starts again from it, as at the lock. With
 * onsets the onset feature fits and scores (where the window has onsets),
 * as it places the cue's line (onset_line). */
static void cue_refine(mar_follow *f)
{
    size_t ages = (size_t)(f->t + 1 - f->cue_onset);
    if (f->cue_fits >= CUE_FITS || ages > f->tk.window || f->seg_start > f->cue_onset) {
        f->cue_refine = 0;      /* the tracker's window holds it all, or the music since is not one line */
        return;
    }
    if (!cue_fit_now(f, ages))
        return;
    double r, d, kappa;
    double fit = line_fit(f, ages, &r, &d, &kappa);
    if (!(fit >= f->opt.track_threshold) || !lockable_peak(f, fit, kappa))
        return;                                                 /* no clear line: the tracker's stays */
    int ch = 0;
    if (f->onsets) {
        double r2, d2, kappa2;
        if (line_fit_ch(f, 1, ages, &r2, &d2, &kappa2) >= f->opt.track_threshold && kappa2 > 0.0)
            ch = 1, r = r2, d = d2;
    }
    double line_now = f->cue_from + r * ((double)ages - 0.5) + d;       /* [stored ticks] */
    double apart_now = line_now - f->kf.p, apart_onset = apart_now - (r - f->kf.r) * (double)ages;
    double lead = fisher(line_score(f, ch, line_now, r, ages))
                - fisher(line_score(f, ch, f->kf.p, f->kf.r, ages));
    if (fmax(fabs(apart_now), fabs(apart_onset)) > 1.0 && lead >= cue_lead(f, ages)) {
        f->kf.p = line_now;
        f->kf.r = r;
        double rate_sd = 1.0 / (double)ages;                    /* a tick over the fit [1] */
        mar_kf_init(&f->kf, 0.25, rate_sd * rate_sd);
    }
}

/* Start the near search around `centre` now [stored ticks], moving at
 * rate r, on the live frames of step `from` on. */
static void start_near(mar_follow *f, double centre, double r, uint64_t from)
{
    f->near = 1;
    f->near_p = centre;
    f->near_r = r > 0.0 ? r : 1.0;
    f->near_from = from;
    f->near_end = f->t + f->tk.near;
    f->near_prev = NAN;
    f->near_confirmed = 0;
    f->alt_p = NAN;
    f->alt_prev = NAN;
    f->alt_confirmed = 0;
}

/* The highest local maximum of rho[0 .. 2 lags] at least NEAR_SEP from
 * lag d [ticks]: the best rival of the peak there [1] (-1: none). */
static double best_rival(const double *rho, int lags, double d)
{
    int b = (int)lround(d) + lags;
    double rival = -1.0;
    for (int i = 1; i < 2 * lags; i++)
        if (abs(i - b) >= NEAR_SEP && rho[i] >= rho[i - 1] && rho[i] >= rho[i + 1] && rho[i] > rival)
            rival = rho[i];
    return rival;
}

/* The live frames since the restart against the stored music around
 * `centre` [stored ticks], at lags -NEAR_LAGS .. NEAR_LAGS: the offset d
 * [ticks] of a peak that is good, sharp and leads by the lock margin every
 * other peak within NEAR_RIVAL_LAGS, else NAN; *h_out: the best height
 * within reach [1] (-1: too little or too flat audio). Rivals lie beyond
 * the reach too: music repeats by the bar (1-2.5 s), so when the tape was
 * wound while stopped the peak within reach may be a bar off a better one
 * outside. */
static double near_peak(mar_follow *f, double centre, double *h_out)
{
    *h_out = -1.0;
    size_t ages = usable(f, f->near_from, f->tk.verify_window);
    long j0;
    double c;
    size_t m = ages >= f->tk.min_window ? resample(f, centre, f->near_r, ages, &j0, &c) : 0;
    if (m < f->tk.min_window / 2)
        return NAN;
    double rho[2 * NEAR_RIVAL_LAGS + 1], h, kappa;
    int edge;
    if (correlate(f, 0, m, j0, NEAR_LAGS, rho) < f->opt.quiet_db)
        return NAN;
    double d = mar_corr_peak(rho, NEAR_LAGS, &h, &kappa, &edge);
    *h_out = h;
    double lead = lock_lead(f, m);
    if (edge || !lockable_peak(f, h, kappa) || fisher(h) - fisher(best_rival(rho, NEAR_LAGS, d)) < lead)
        return NAN;
    /* a clear peak within reach: only now the rivals beyond it (three
     * times the lags, so three times the work) */
    correlate(f, 0, m, j0, NEAR_RIVAL_LAGS, rho);
    if (fisher(h) - fisher(best_rival(rho, NEAR_RIVAL_LAGS, d)) < lead)
        return NAN;
    return d;
}

/* d [ticks] found again within a tick of *prev: counts the run in *run;
 * 1 once it is LOCK_CONFIRM long. */
static int stays_put(double d, double *prev, int *run)
{
    *run = !isnan(*prev) && fabs(d - *prev) <= 1.0 ? *run + 1 : 1;
    *prev = d;
    return *run >= LOCK_CONFIRM;
}

/* The near search, one tick: only places within its reach of the resumed
 * one compete, so a second or so of music tells them apart where the
 * whole-piece search would wait for a longer window. It locks on a clear
 * peak (near_peak) that stays put (within a tick) LOCK_CONFIRM ticks in a
 * row. Without one it also looks around the place the music would have
 * reached had the tape not stopped: a volume turn down in a quiet passage
 * reads as a stop, and when the music rises again it plays on from there,
 * seconds away. That place must show its peak within ALT_REACH of its
 * line, lead the resumed place's best height by the lock margin and stay
 * put as well. */
static void near_search(mar_follow *f, uint32_t *flags)
{
    f->near_p += f->near_r;
    f->alt_p += f->near_r;                            /* (NAN stays NAN) */
    if (f->t >= f->near_end) {
        f->near = 0;
        return;
    }
    double h, d = near_peak(f, f->near_p, &h);
    if (!isnan(d)) {
        if (stays_put(d, &f->near_prev, &f->near_confirmed)) {
            cand e = {.p = f->near_p + d, .r = f->near_r, .fine = h, .since = f->near_from};
            lock_on(f, &e, flags);
        }
        return;
    }
    f->near_confirmed = 0;
    if (isnan(f->alt_p) || fabs(f->alt_p - f->near_p) < 2.0 * NEAR_LAGS)
        return;                                       /* no other place, or within reach already */
    double ha, da = near_peak(f, f->alt_p, &ha);
    size_t m = usable(f, f->near_from, f->tk.verify_window);
    if (isnan(da) || fabs(da) > ALT_REACH || fisher(ha) - fisher(h) < lock_lead(f, m > 1 ? m : 1)) {
        f->alt_confirmed = 0;
        return;
    }
    if (stays_put(da, &f->alt_prev, &f->alt_confirmed)) {
        cand e = {.p = f->alt_p + da, .r = f->near_r, .fine = ha, .since = f->near_from};
        lock_on(f, &e, flags);
    }
}

static void pause_now(mar_follow *f);

/* While searching there is no place to expect music at, so a stop shows
 * only as a run of steady hiss near the noise floor. During SEARCH_GAP_S or
 * more such frames the search does not lock; when sound returns, it starts
 * again on the frames from there on: those before may belong to another
 * stretch of tape (it may have been wound), and a silence inside the
 * window would be matched to a quiet passage of the stored music. */
static void search_gap(mar_follow *f)
{
    double db = f->ldb[ring(f, f->t)];
    if (db <= f->nf + NEAR_FLOOR_DB
        && (f->gap_run == 0 || fmax(f->gap_hi, db) - fmin(f->gap_lo, db) <= STEADY_RANGE_DB)) {
        if (f->gap_run == 0)
            f->gap_lo = f->gap_hi = db;
        f->gap_lo = fmin(f->gap_lo, db);
        f->gap_hi = fmax(f->gap_hi, db);
        f->gap_run++;
        /* lost, but the music was somewhere a moment ago: a tape that
         * stands stops there, as in a pause seen while following (the
         * flywheel would run on through the stop, seconds ahead by its end) */
        if (f->gap_run == f->tk.search_gap && f->ever && f->state == MAR_FOLLOW_SEARCHING) {
            f->silent_start = f->t + 1 - f->gap_run;
            f->silent_lo = f->gap_lo;
            f->silent_hi = f->gap_hi;
            pause_now(f);
        }
        return;
    }
    if (f->gap_run >= f->tk.search_gap && db > f->gap_hi + MIN_RESUME_DB) {
        stop_search(f);
        start_search(f, f->t);
    }
    f->gap_run = 0;
}

static void run_search(mar_follow *f, uint32_t *flags)
{
    f->c.search_steps++;
    *flags |= MAR_FOLLOW_F_SEARCH;
    cand *tr = NULL;
    for (int i = 0; i < POOL; i++) {                 /* candidates move with the music */
        cand *e = &f->pool[i];
        if (!e->used)
            continue;
        if (e->track)
            tr = e;
        else
            e->p += e->r;
    }
    if (f->ever && f->state != MAR_FOLLOW_SEARCHING && f->state != MAR_FOLLOW_WAITING && !f->cue_pending) {
        /* the tracker's own hypothesis competes as the "track" entry. Not
         * a pending cue's: cue_fit judges that line, and beside it the
         * search is an unknown start's (the entry took verifications and
         * a wrong cue was found up to 0.42 s later: docs/music.md) */
        if (!tr) {
            for (int i = 0; i < POOL && !tr; i++)
                if (!f->pool[i].used)
                    tr = &f->pool[i];
            if (!tr)
                tr = &f->pool[0];
            memset(tr, 0, sizeof *tr);
            tr->used = 1;
            tr->track = 1;
            tr->fine = NAN;
            tr->since = f->seg_start;
            tr->checked = f->t;
        }
        tr->p = f->kf.p;
        tr->r = f->kf.r > 0.0 ? f->kf.r : 1.0;
    } else if (tr) {
        tr->used = 0;
    }
    prepare_search(f);
    if (f->m_eff == 0)
        return;
    sweep(f, (size_t)f->opt.search_budget);
    cand *e = next_to_verify(f);
    if (e)
        verify(f, e);
    dedup(f);
    /* no lock during a stop: its silence would be matched to a quiet passage */
    cand *best = f->gap_run >= f->tk.search_gap ? NULL : lock_choice(f);
    if (best)
        lock_on(f, best, flags);
}

/* A frame's squared misfit to the level expected [dB^2], capped so that
 * one odd note does not decide. */
static double misfit(double db, double expected)
{
    double d = db - expected;
    return fmin(LOW_DB * LOW_DB, d * d);
}

/* The least of costs offered in order 0, 1, ... [dB^2]; those within
 * STOP_TIE_DB2 of it right after it tie with it: flat_min_middle is the
 * middle of that flat stretch. */
typedef struct {
    double best;
    size_t first, last;
} flat_min;

static void flat_min_offer(flat_min *m, size_t i, double cost)
{
    if (cost < m->best - STOP_TIE_DB2)
        m->best = cost, m->first = m->last = i;
    else if (cost <= m->best + STOP_TIE_DB2 && m->last + 1 == i)
        m->last = i;
}

static size_t flat_min_middle(const flat_min *m) { return (m->first + m->last + 1) / 2; }

/* Where the tape stopped: the step of the first silent frame. It lies after
 * the last frame clearly over the silence heard now (quiet music may stand
 * only a few dB over the hiss) and no later than the silent run's start.
 * Between the two, each frame should show the stored music at the position
 * then (plus the gain, over the hiss) before the stop and the silence's
 * level from it on: the split with the least squared misfit [dB^2] wins
 * (each frame's misfit capped, so one odd note does not decide). Where the
 * music was as quiet as the hiss the misfit stays flat: the middle of that
 * flat stretch. */
static uint64_t stop_step(const mar_follow *f, uint64_t oldest)
{
    double hiss = 0.5 * (f->silent_lo + f->silent_hi);          /* [dB] */
    double loud_db = hiss + NEAR_FLOOR_DB;                        /* surely music, not hiss [dB] */
    uint64_t last_loud = f->t;
    while (last_loud > oldest) {
        double db = f->ldb[ring(f, last_loud)];
        if (!isnan(db) && db >= loud_db)
            break;
        last_loud--;
    }
    uint64_t lo_step = last_loud + 1, hi_step = f->silent_start > lo_step ? f->silent_start : lo_step;
    if (hi_step - lo_step >= STOP_SPAN)
        lo_step = hi_step + 1 - STOP_SPAN;
    size_t n = (size_t)(hi_step - lo_step + 1);
    /* splits s in [lo_step, hi_step]; frames after hi_step are silence for all of them */
    double music_sum[STOP_SPAN + 1], silence_sum[STOP_SPAN + 1];
    music_sum[0] = silence_sum[0] = 0.0;
    for (size_t i = 0; i < n; i++) {
        uint64_t q = lo_step + i;
        double db = f->ldb[ring(f, q)], m = 0.0, h = 0.0;
        if (!isnan(db)) {
            double music = stored_db_at(f, f->lpos[ring(f, q)] - 0.5 * f->kf.r - 0.5) + f->gain;
            m = misfit(db, over_hiss_db(music, hiss));
            h = misfit(db, hiss);
        }
        music_sum[i + 1] = music_sum[i] + m;
        silence_sum[i + 1] = silence_sum[i] + h;
    }
    flat_min split = {INFINITY, 0, 0};
    for (size_t i = 0; i < n; i++)
        flat_min_offer(&split, i, music_sum[i] + silence_sum[n] - silence_sum[i]);
    return lo_step + flat_min_middle(&split);
}

/* The recorder stopped: back to where it stopped, and hold there. */
static void pause_now(mar_follow *f)
{
    f->gain_heard = 0.0;                              /* the knob may turn unheard while stopped */
    uint64_t oldest = f->t + 1 > f->hcap - 1 ? f->t + 2 - f->hcap : 0;
    if (oldest < f->seg_start)
        oldest = f->seg_start;
    uint64_t stop = stop_step(f, oldest);             /* first silent step */
    double at = f->kf.p;
    if (stop >= 1 && stop - 1 >= oldest && f->t - stop < f->hcap - 1)
        at = f->lpos[ring(f, stop - 1)];
    f->frozen = at - 0.5 * f->kf.r;
    f->stop_at = stop >= oldest && stop <= f->t ? stop : f->t;
    f->kf.p = f->frozen;
    f->state = MAR_FOLLOW_PAUSED;
    f->unproven = 0;
    f->loud_run = 0;
    f->pause_db = f->ldb[ring(f, f->t)];              /* a silent frame (detect_pause saw it) */
    f->pause_dev = 0.5 * (f->silent_hi - f->silent_lo);
    f->pause_start = f->t;
    /* resume on frames halfway up from the silence to the music expected where it stopped */
    double expected = -INFINITY;
    for (size_t k = 0; k < f->tk.resume_look; k++)
        expected = fmax(expected, stored_db_at(f, f->frozen + (double)k));
    double margin = expected + f->gain - f->pause_db;
    f->resume_db = fmin(RESUME_DB, fmax(MIN_RESUME_DB, 0.5 * margin));
    f->c.pauses++;
    f->near = 0;
    stop_search(f);
}

/* Where the tape restarted, as the stored frame [stored ticks] that the
 * onset frame (step `onset`) shows: the frozen place, or further on when
 * the tape restarted in a gap of the music and ran on unheard. Each
 * candidate puts the stored music along the line through it, at the rate,
 * on the frames since the pause began: before the frozen place the tape
 * stood (the silence's level), from it on the music plus the gain over the
 * silence (powers added). The one with the least squared misfit [dB^2]
 * wins (each frame's capped, as in stop_step), the middle of a flat
 * stretch of them (music as quiet as the hiss: anywhere in it). */
static double restart_place(const mar_follow *f, uint64_t onset)
{
    if (!f->have_gain)
        return f->frozen;
    double r = f->kf.r > 0.0 ? f->kf.r : 1.0;
    uint64_t back = (uint64_t)ceil((double)f->tk.gap_ahead / r) + 1;
    uint64_t lo = onset > f->pause_start + back ? onset - back : f->pause_start;
    double j = floor(f->frozen);
    flat_min place = {INFINITY, 0, 0};
    for (size_t c = 0; c < f->tk.gap_ahead; c++) {
        double from = fmax(f->frozen, j + (double)c), cost = 0.0;
        for (uint64_t q = lo; q <= f->t; q++) {
            double db = f->ldb[ring(f, q)];
            if (isnan(db))
                continue;
            double x = from + r * ((double)q - (double)onset);
            cost += misfit(db, x >= f->frozen ? over_hiss_db(stored_db_at(f, x) + f->gain, f->pause_db)
                                              : f->pause_db);
        }
        flat_min_offer(&place, c, cost);
    }
    return fmax(f->frozen, j + (double)flat_min_middle(&place));
}

/* In a pause: two frames clearly over the level of the silence resume the
 * tape where it stopped, from the middle of the first of them. */
static int resume_now(mar_follow *f, int have, uint32_t *flags)
{
    double db = have ? f->ldb[ring(f, f->t)] : NAN;
    /* over the silence by resume_db, or by a few of its own wobbles (hiss is steady) */
    double over = fmin(f->resume_db, fmax(MIN_RESUME_DB, RESUME_SIGMAS * f->pause_dev));
    if (have && db > f->pause_db + over) {
        f->loud_run++;
    } else {
        f->loud_run = 0;
        if (have) {                                   /* follow the silence's level and its wobble */
            double prev = f->ldb[ring(f, f->t - 1)];
            if (!isnan(prev) && f->t > f->pause_start)
                f->pause_dev += f->tk.pause_alpha * (fabs(db - prev) - f->pause_dev);
            f->pause_db += f->tk.pause_alpha * (db - f->pause_db);
        }
    }
    if (f->loud_run < 2)
        return 0;
    if (f->opt.mode == MAR_FOLLOW_PAPER)
        f->kf.r = 1.0;
    /* the music began where the frames first rose clearly over the silence
     * (a quiet entry rises slowly): look back from the run */
    uint64_t onset = f->t + 1 - f->loud_run, limit = f->t > f->tk.onset_back ? f->t - f->tk.onset_back : 0;
    double rise = fmax(ONSET_DB, ONSET_SIGMAS * f->pause_dev);
    if (limit < f->pause_start)
        limit = f->pause_start;
    while (onset > limit + 1) {
        double db = f->ldb[ring(f, onset - 1)];
        if (isnan(db) || !(db > f->pause_db + rise))
            break;
        onset--;
    }
    double run = (double)(f->t + 1 - onset);
    double from = restart_place(f, onset);
    f->kf.p = from + f->kf.r * (run - 0.5);
    f->seg_start = onset;
    f->probation = 1;
    f->probation_ok = 0;
    f->doubt = f->regaining = 0;
    f->h_fast = f->h_slow;
    f->state = MAR_FOLLOW_HOLDING;
    f->measured = 0;
    f->last_good = f->t;
    f->bad_since = f->quiet_since = 0;
    f->silent_run = 0;
    mar_kf_init(&f->kf, RESUME_VAR, f->kf.P11 + 1e-6);
    start_near(f, f->kf.p, f->kf.r, onset);
    if (f->kf.r > 0.0)               /* had the tape not stopped (a fade read as a stop) */
        f->alt_p = f->frozen + f->kf.r * (double)(f->t + 1 - f->stop_at);
    f->c.resumes++;
    *flags |= MAR_FOLLOW_F_JUMP;
    return 1;
}

/* The live music of the last second stands clearly over the noise floor
 * (on average CLEAR_DB over it): a failing correlation there is not noise
 * hiding a quiet passage. */
static int clear_music(const mar_follow *f)
{
    double sum = 0.0;
    size_t cnt = 0, ages = usable(f, f->seg_start, f->tk.clear_window);
    for (size_t i = 0; i < ages; i++) {
        double db = f->ldb[ring(f, f->t - i)];
        if (!isnan(db))
            sum += db, cnt++;
    }
    return cnt >= f->tk.clear_window / 2 && sum / (double)cnt > f->nf + CLEAR_DB;
}

/* Following (LOCKED or HOLDING): one measurement, then the state. */
static void follow(mar_follow *f, int have, uint32_t *flags)
{
    int quiet = 0, ok;
    if (f->opt.mode == MAR_FOLLOW_PAPER) {
        int step;
        ok = track_paper(f, &quiet, &step, flags);
        f->kf.p += (double)step;
        f->kf.r = (double)step;
    } else {
        ok = track_smooth(f, &quiet, flags);
    }
    /* the volume knob turns whether or not the correlation is clear (a ramp
     * in a quiet passage would otherwise look like a pause) */
    update_gain(f, f->kf.p, f->kf.r > 0.0 ? f->kf.r : 1.0, 1);
    if (ok) {
        f->measured = 1;
        f->probation_ok++;
        f->c.measurements++;
        f->last_good = f->t;
        f->bad_since = f->quiet_since = 0;
        f->regain_ok++;
    } else if (quiet || !have) {
        f->quiet_since++;
        f->conf *= 0.99;
    } else {
        f->c.rejected++;
        f->bad_since++;
        f->conf *= 0.97;
        f->regain_ok = 0;
        f->regain_bad++;
    }
    /* one fitting measurement after a long bad stretch proves little (hiss
     * against a wrong place can pass): a run of them ends the hold */
    if (f->regaining && f->regain_ok >= f->tk.regain) {
        f->regaining = 0;
        if (!f->doubt && !f->probation)
            stop_search(f);
    }
    if (quiet == 1)
        *flags |= MAR_FOLLOW_F_QUIET;
    double since = (double)(f->t - f->last_good);
    /* a second without a fitting measurement: the place is the flywheel's
     * guess (a stop under the hiss goes unnoticed, and bars alike fit a
     * place bars off); not LOCKED again on a weak fit, only once the
     * confidence is back (or by a lock) */
    if (since > f->tk.long_hold)
        f->unproven = 1;
    else if (f->conf >= PROOF_CONF)
        f->unproven = 0;
    /* the tracking correlation collapsed while the music is clear: the tape
     * may have jumped to a place that resembles this one (the same drums):
     * doubt the place, and let the search (with this place in its pool)
     * decide; only a lock ends the doubt */
    if (!f->doubt && f->measured && !quiet && f->h_fast < f->h_slow - doubt_drop(f) && clear_music(f)
        && f->silent_run == 0) {
        f->doubt = 1;
        uint64_t back = f->tk.window / 2;
        uint64_t from = f->t + 1 > back ? f->t + 1 - back : 0;
        if (f->h_low_since && f->h_low_since - 1 > from)
            from = f->h_low_since - 1;
        start_search(f, from);
    }
    /* after a resume, the place is on probation until the near search has
     * locked (which ends it) or given up and the tracker has confirmed the
     * place for lock_window / 2 frames; unclear music in that time sends it
     * back to the search */
    if (f->probation && !f->near && f->probation_ok >= f->tk.lock_window / 2 && f->bad_since == 0
        && !f->doubt)
        f->probation = 0;
    /* LOCKED: a measurement confirmed the place since the last (re)start, recently */
    f->state = since <= f->tk.hold_after && f->measured && !f->doubt && !f->probation && !f->regaining
        && !f->unproven && !f->cue_pending ? MAR_FOLLOW_LOCKED : MAR_FOLLOW_HOLDING;
    /* frames from well before the measurements went bad may belong to
     * another place of the tape (a jump): the search starts after them */
    uint64_t bad_start = f->t + 1 - f->bad_since;
    uint64_t from = bad_start > f->tk.min_window ? bad_start - f->tk.min_window : 0;
    if ((double)f->bad_since >= f->tk.lost_after || since >= f->tk.quiet_lost_after
        || (f->probation && f->bad_since >= f->tk.probation_bad)
        || (f->regaining && (double)f->regain_bad >= f->tk.lost_after)) {
        uint64_t at = f->probation && f->seg_start > from ? f->seg_start : from;
        f->state = MAR_FOLLOW_SEARCHING;
        f->probation = f->doubt = f->regaining = 0;
        /* beside a pending cue the search is an unknown start's, listening
         * from the first frame: started afresh here, it found a wrong cue's
         * place up to 0.14 s later than from an unknown start */
        if (!f->cue_pending) {
            stop_search(f);
            start_search(f, at);
        }
    } else if ((double)f->bad_since >= f->tk.search_after) {
        start_search(f, from);
        if (!f->regaining)
            f->regaining = 1, f->regain_ok = 0, f->regain_bad = f->bad_since;
    } else if (f->probation || f->cue_pending) {
        /* an unproven place: the search decides. Beside a pending cue it
         * runs on from the onset until the cue locks: stopped by a fitting
         * measurement, a wrong cue's search started afresh at the cue's
         * refutation and found the place up to 1.8 s later than from an
         * unknown start (bench sync, docs/music.md) */
        start_search(f, f->seg_start);
    } else if (ok && f->searching && !f->doubt && !f->regaining) {
        stop_search(f);
    }
}

/* --- the model (mode MAR_FOLLOW_MODEL) ----------------------------------
 *
 * The smooth mode's tracker (track_smooth) and whole-piece search (sweep,
 * verify) measure; two beliefs of the tape deck model (mar_follow_deck.h)
 * decide, where the smooth mode has its rules:
 *   motion: playing or stopped, from each frame's level against the music
 *     expected at the place and the noise floor: a stop is PAUSED, a start
 *     resumes from where it stopped;
 *   place: the followed place, each of the search's verified candidates and
 *     "somewhere else", each scored on the same live window: the followed
 *     place has the prior, a candidate that of a jump. The followed place's
 *     posterior is the confidence (LOCKED from lock_confidence on); a
 *     candidate more probable than it takes over (a jump, or a first lock).
 * The cue's start (music_started) is still the smooth mode's. */

/* The music a playing deck shows now [dB]: the stored level at the place
 * plus the volume. */
static double model_expected_db(const mar_follow *f)
{
    return stored_db_at(f, f->kf.p - 0.5 * f->kf.r - 0.5) + f->gain;
}

/* The motion belief takes this frame; the deck stops (PAUSED, back to where
 * the evidence for it began) or starts (from where it stopped, at the first
 * frame of the evidence for it). */
static void model_motion(mar_follow *f, uint32_t *flags)
{
    double db = f->ldb[ring(f, f->t)];
    double ev;
    if (f->state != MAR_FOLLOW_PAUSED && !f->probation) {
        ev = mar_deck_level_evidence(db, model_expected_db(f), f->nf, f->opt.level_sigma, f->opt.level_cap);
    } else {
        /* stopped, or restarted and not yet measured, the volume may have
         * changed: music is any frame that stands out of the hiss heard
         * since the stop */
        ev = mar_deck_hiss_evidence(db, f->pause_db, fmax(MODEL_HISS_SIGMA, f->pause_dev), MODEL_MUSIC_SPAN,
                                    f->opt.level_cap);
        if (ev > 0.0) {                          /* hiss: follow its level and wobble */
            double prev = f->ldb[ring(f, f->t - 1)];
            if (!isnan(prev))
                f->pause_dev += f->tk.pause_alpha * (fabs(db - prev) - f->pause_dev);
            f->pause_db += f->tk.pause_alpha * (db - f->pause_db);
        }
    }
    if (ev <= 0.0)
        f->stop_run = f->t + 1;                 /* a stop began after this frame, if at all */
    if (ev >= 0.0)
        f->play_run = f->t + 1;
    mar_deck_motion_update(&f->motion, ev);
    int stopped = mar_deck_stopped(&f->motion) > 0.5;
    if (stopped && f->state != MAR_FOLLOW_PAUSED) {
        uint64_t stop = f->stop_run > f->seg_start ? f->stop_run : f->seg_start;
        double at = stop >= 1 && f->t - (stop - 1) < f->hcap - 1 ? f->lpos[ring(f, stop - 1)] : f->kf.p;
        f->frozen = f->kf.p = at;
        f->stop_at = stop;
        f->pause_db = db;
        f->pause_dev = 0.0;
        f->state = MAR_FOLLOW_PAUSED;
        f->c.pauses++;
        stop_search(f);
    } else if (!stopped && f->state == MAR_FOLLOW_PAUSED) {
        uint64_t onset = f->play_run <= f->t ? f->play_run : f->t;
        if (f->kf.r <= 0.0)
            f->kf.r = 1.0;
        f->kf.p = f->frozen + f->kf.r * ((double)(f->t + 1 - onset) - 0.5);
        mar_kf_init(&f->kf, RESUME_VAR, f->kf.P11 + 1e-6);
        f->seg_start = onset;
        f->state = MAR_FOLLOW_HOLDING;          /* LOCKED again after a measurement at the restarted place */
        f->have_gain = 0;                       /* the knob may have turned meanwhile: measured again */
        f->probation = 1;                       /* (track_smooth: a short window places the restart) */
        f->c.resumes++;
        *flags |= MAR_FOLLOW_F_JUMP;
    }
}

/* The search beside, all the time: its candidates are the place belief's
 * rivals. While the followed place is clearly the most probable, it looks
 * on at a fraction of its pace (MODEL_IDLE): a jump lowers that place's
 * posterior (its fit falls under the rest of the piece's), and the search
 * runs at full pace again. */
static void model_search(mar_follow *f, uint32_t *flags)
{
    int idle = f->proven && f->conf >= f->opt.lock_confidence;
    if (!f->searching)
        start_search(f, f->seg_start);
    f->c.search_steps++;
    *flags |= MAR_FOLLOW_F_SEARCH;
    for (int i = 0; i < POOL; i++)
        if (f->pool[i].used)
            f->pool[i].p += f->pool[i].r;
    prepare_search(f);
    if (f->m_eff == 0)
        return;
    size_t budget = (size_t)f->opt.search_budget;
    sweep(f, idle ? (budget + MODEL_IDLE - 1) / MODEL_IDLE : budget);
    cand *e = idle && f->t % MODEL_IDLE ? NULL : next_to_verify(f);
    if (e)
        verify(f, e);
    dedup(f);
}

/* The best fit [1] of the last sweep's best places that are not listed
 * (more than DISTINCT from the followed place and from each of the n
 * candidates in who[]), each scored on the newest `ages` frames at the
 * rate of the best listed place, one rescored per tick: the pool keeps 16
 * places, and in music that repeats more than 16 can fit a short window. */
static double unlisted_rho(mar_follow *f, cand *const *who, size_t n, size_t ages)
{
    double r = f->located ? f->kf.r : 1.0, top = -INFINITY;
    for (size_t i = 0; i < n && !f->located; i++)
        if (who[i]->rho > top)
            top = who[i]->rho, r = who[i]->r;
    if (!(r > 0.0))
        r = 1.0;
    double best = 0.0;
    int rescored = 0;
    for (int i = 0; i < PEAKS; i++) {
        sweep_peak *k = &f->last_peaks[(f->t + (uint64_t)i) % PEAKS];
        if (!k->used)
            continue;
        double p = k->p + r * (double)(f->t - k->t);
        int listed = f->located && fabs(p - f->kf.p) < DISTINCT;
        for (size_t j = 0; j < n && !listed; j++)
            listed = fabs(p - who[j]->p) < DISTINCT;
        if (listed)
            continue;
        if (!rescored) {
            k->rho = score_on(f, p, r, ages);
            rescored = 1;
        }
        if (!isnan(k->rho))
            best = fmax(best, k->rho);
    }
    return best;
}

/* The place belief: the followed place (when there is one), the pool's
 * verified candidates and somewhere else, each scored on the same newest
 * live frames (one candidate rescored per tick).
 *
 * Not proven yet (nothing followed, or only a cue or a place just taken
 * over): the scores of this window decide, the followed place with its
 * prior (1 - MODEL_CUE_DOUBT),
 * somewhere else as the worst candidate kept (the search keeps the best
 * places). Once a whole sweep has been scored, the most probable place
 * is taken from lock_confidence on: a candidate (a lock), or the cue's
 * place (proven).
 *
 * Proven: the evidence adds up over time, a window's worth in a window's
 * time (each log weight moves by its log-likelihood, less the best one's,
 * over the window's length per tick); somewhere else is a place that fits
 * a little less well (MODEL_ELSE_Z) than the music usually fits here
 * (rho_usual); no place falls further behind the best than the tape
 * jumping there within a tick (log_share); a candidate more probable than
 * the followed place takes over, and proves itself as a cue does.
 *
 * Returns the followed place's posterior (0 with none followed). */
static double model_place(mar_follow *f, uint32_t *flags)
{
    if (f->proven && f->conf >= f->opt.lock_confidence && f->t - f->belief_t < MODEL_IDLE)
        return f->conf;                         /* clear: looked at every MODEL_IDLE ticks */
    size_t ages = usable(f, f->located ? f->seg_start : f->search_from, f->tk.window);
    if (ages < f->tk.min_window)
        return f->conf;
    double n_eff = (double)ages * (double)f->main->bands * f->tk.evidence_per_frame;
    double lead_rho = f->located ? score_on(f, f->kf.p, f->kf.r > 0.0 ? f->kf.r : 1.0, ages) : NAN;
    for (int k = 0; k < POOL; k++) {            /* the next verified candidate gets a fresh score */
        cand *e = &f->pool[f->rescore = (f->rescore + 1) % POOL];
        if (e->used && !isnan(e->fine)) {
            e->rho = score_on(f, e->p, e->r, ages);
            break;
        }
    }
    double ll[POOL + 1], log_w[POOL + 1], post[POOL + 1];
    cand *who[POOL];
    size_t n = 0, best = 0;
    double rho_else = 0.0;
    for (int i = 0; i < POOL; i++) {
        cand *e = &f->pool[i];
        /* the followed place's own entry; proven, the tracker's lags reach
         * its neighbours, not yet (a cue's onset is placed roughly) they are
         * candidates in their own right */
        double near = f->proven ? DISTINCT : TRACK_SEP;
        if (!e->used || isnan(e->fine) || isnan(e->rho) || (f->located && fabs(e->p - f->kf.p) < near))
            continue;
        rho_else = n ? fmin(rho_else, e->rho) : e->rho;
        who[n] = e;
        ll[n++] = mar_deck_place_evidence(e->rho, n_eff);
    }
    if (!f->proven)
        rho_else = fmax(rho_else, unlisted_rho(f, who, n, ages));
    ll[n] = mar_deck_place_evidence(lead_rho, n_eff);       /* (with one followed) */
    size_t places = n + (size_t)f->located;
    if (!f->proven) {
        /* the cue's prior covers its neighbourhood (its onset is placed roughly) */
        double doubt = f->located ? log(MODEL_CUE_DOUBT) : 0.0;
        for (size_t i = 0; i < n; i++)
            log_w[i] = (fabs(who[i]->p - f->kf.p) < DISTINCT ? 0.0 : doubt) + ll[i];
        log_w[n] = ll[n];
        mar_deck_posterior(log_w, places, doubt + mar_deck_place_evidence(rho_else, n_eff), post);
        for (size_t i = 1; i < n; i++)
            if (post[i] > post[best])
                best = i;
        int looked = f->sweeps_done >= 1;
        if (f->located && looked && post[n] >= f->opt.lock_confidence) {
            f->proven = 1;                      /* the cue's place, confirmed: its evidence adds up from now */
            f->belief_t = f->t;
        }
        if (n == 0 || !looked || who[best]->frames < f->tk.min_window || who[best]->confirmed < 1
            || post[best] < f->opt.lock_confidence)
            return f->located ? post[n] : n ? post[best] : 0.0;
    } else {
        /* (a shorter window fits better: the usual fit is that of whole windows) */
        if (ages == f->tk.window && !isnan(lead_rho))
            f->rho_usual = isnan(f->rho_usual) ? lead_rho
                : f->rho_usual + fmin(1.0, (double)(f->t - f->belief_t) / f->tk.usual) * (lead_rho - f->rho_usual);
        double usual = isnan(f->rho_usual) ? 0.0 : tanh(atanh(fmin(f->rho_usual, 0.999)) - MODEL_ELSE_Z);
        double ll_else = mar_deck_place_evidence(fmax(rho_else, usual), n_eff);
        double top = fmax(ll_else, ll[n]);
        for (size_t i = 0; i < n; i++)
            top = fmax(top, ll[i]);
        /* the evidence of the ticks since the last update, a window's worth per window */
        double W = (double)f->tk.window / (double)(f->t - f->belief_t), most = -INFINITY;
        f->lead_belief += (ll[n] - top) / W;
        f->else_belief += (ll_else - top) / W;
        for (size_t i = 0; i < n; i++) {
            if (!isnan(who[i]->belief))
                who[i]->belief += (ll[i] - top) / W;
            most = fmax(most, who[i]->belief);
        }
        most = fmax(most, fmax(f->lead_belief, f->else_belief));
        double floor_w = most + f->tk.log_share;    /* the tape may always have jumped there */
        f->lead_belief = fmax(f->lead_belief, floor_w);
        f->else_belief = fmax(f->else_belief, floor_w);
        for (size_t i = 0; i < n; i++)
            log_w[i] = who[i]->belief = isnan(who[i]->belief) ? floor_w : fmax(who[i]->belief, floor_w);
        log_w[n] = f->lead_belief;
        mar_deck_posterior(log_w, places, f->else_belief, post);
        f->belief_t = f->t;
        for (size_t i = 1; i < n; i++)
            if (post[i] > post[best])
                best = i;
        if (n == 0 || who[best]->frames < f->tk.min_window || post[best] <= post[n])
            return post[n];
    }
    double taken = post[best];
    int jumped = f->proven;                     /* taken over from a followed place, not a lock */
    lock_on(f, who[best], flags);               /* (clears the pool) */
    mar_kf_init(&f->kf, 1.0, MODEL_LOCK_RATE_VAR);
    f->located = 1;
    /* a first lock has beaten a whole sweep's candidates on its window; a
     * place taken over from another has only beaten the followed one, and
     * proves itself as a cue does */
    model_follow_afresh(f, !jumped);
    return taken;
}

/* One step of the model (after take_frame). */
static void step_model(mar_follow *f, int have, uint32_t *flags)
{
    /* 1. the clock */
    if (f->state == MAR_FOLLOW_WAITING) {
        uint64_t onset;
        if (music_started(f, have, &onset)) {
            play_from_cue(f, onset);
            f->cue_pending = 0;                 /* the place belief decides, with the cue as its prior */
            f->located = 1;
            stop_search(f);                     /* a fresh sweep over the music since its onset */
            start_search(f, onset);
            model_follow_afresh(f, 0);          /* a cue is a claim until the search has looked around */
        }
    } else if (f->state != MAR_FOLLOW_PAUSED && f->located) {
        mar_kf_predict(&f->kf, f->tk.rate_var);
    }
    /* 2. the motion, where the place is believed (the music expected
     *    elsewhere says nothing about whether this music plays) */
    if (f->located && have && f->have_gain && f->state != MAR_FOLLOW_WAITING
        && (f->conf >= 0.5 || f->state == MAR_FOLLOW_PAUSED))
        model_motion(f, flags);
    /* 3. the tracker */
    int quiet = 0;
    if (f->located && f->state != MAR_FOLLOW_PAUSED && f->state != MAR_FOLLOW_WAITING) {
        if (track_smooth(f, &quiet, flags)) {
            f->measured = 1;
            f->probation = 0;
            f->last_good = f->t;
            f->bad_since = 0;
            f->c.measurements++;
        } else if (!quiet && have && ++f->bad_since == (uint64_t)f->tk.hold_after) {
            /* the line went astray (a rate taken from too short a window, a
             * drift): the peaks lie beyond the gate; widen the filter's
             * uncertainty so that its lags reach them again */
            mar_kf_init(&f->kf, fmax(f->kf.P00, MODEL_ASTRAY_VAR_P), fmax(f->kf.P11, MODEL_ASTRAY_VAR_R));
        }
        update_gain(f, f->kf.p, f->kf.r > 0.0 ? f->kf.r : 1.0, f->have_gain ? 1 : f->tk.window);
        if (quiet == 1)
            *flags |= MAR_FOLLOW_F_QUIET;
    }
    /* 4. the search and the place belief (waiting at the cue too: the music
     *    may start elsewhere, or too softly for music_started) */
    if (f->state == MAR_FOLLOW_PAUSED)
        return;
    if (have)
        model_search(f, flags);
    f->conf = model_place(f, flags);            /* (waiting, a lock may end the wait) */
    if (f->state == MAR_FOLLOW_WAITING && !f->located)
        return;
    if (!f->located)
        f->state = MAR_FOLLOW_SEARCHING;
    else
        /* LOCKED: the place proven, probable, and measured recently, since
         * the tape last restarted */
        f->state = f->proven && f->conf >= f->opt.lock_confidence && f->last_good >= f->seg_start
                           && (double)(f->t - f->last_good) <= f->tk.hold_after ? MAR_FOLLOW_LOCKED
                                                                                 : MAR_FOLLOW_HOLDING;
}

void mar_follow_step(mar_follow *f, double live, mar_follow_out *out)
{
    mar_follow_step_onset(f, live, NAN, out);
}

static void step_frame(mar_follow *f, const mar_follow_frame *frame, mar_follow_out *out);

void mar_follow_step_onset(mar_follow *f, double live, double onset, mar_follow_out *out)
{
    const mar_follow_frame frame = {.loudness = live, .onset = onset};
    step_frame(f, isnan(live) ? NULL : &frame, out);
}

/* Steps 1 to 3 of the smooth and the paper mode (after take_frame). */
static void step_rules(mar_follow *f, int have, uint32_t *flags)
{
    /* 1. the clock: where the music is now, before this frame is looked at */
    int resumed = 0;
    uint64_t music_from;
    if (f->state == MAR_FOLLOW_WAITING) {
        if (music_started(f, have, &music_from))
            play_from_cue(f, music_from);
    } else if (f->state == MAR_FOLLOW_PAUSED)
        resumed = resume_now(f, have, flags);
    else if (f->state == MAR_FOLLOW_SEARCHING)
        f->kf.p += f->ever ? f->kf.r : 0.0;                 /* flywheel, or nothing known yet */
    else if (f->opt.mode == MAR_FOLLOW_PAPER)
        ;                                             /* paper: the tracking step moves it */
    else
        mar_kf_predict(&f->kf, f->tk.rate_var);

    /* 2. following: pause, else measure */
    if (f->state == MAR_FOLLOW_LOCKED || f->state == MAR_FOLLOW_HOLDING) {
        if (!resumed && detect_pause(f, have)) {
            if (f->probation) {
                /* silence again where the resumed place expects music: the
                 * place is doubtful; search from here (no position guess) */
                f->probation = f->doubt = f->near = 0;
                f->state = MAR_FOLLOW_SEARCHING;
                f->silent_run = 0;
                stop_search(f);
                start_search(f, f->t + 1);
            } else if (f->cue_pending) {
                /* silence where the cue's line expects music, before the
                 * cue has locked: no evidence of a stop at a place not yet
                 * known; the cue is refuted (the search's gap rule sees a
                 * real stop) */
                refute_cue(f);
                f->silent_run = 0;
            } else {
                pause_now(f);
            }
        }
        else if (!resumed || f->opt.mode == MAR_FOLLOW_SMOOTH)
            follow(f, have, flags);
        if (f->cue_pending && f->cue_fits < CUE_FITS && f->state != MAR_FOLLOW_PAUSED)
            cue_fit(f, flags);
        else if (f->cue_refine && f->state == MAR_FOLLOW_LOCKED && !f->doubt && !f->probation)
            cue_refine(f);
    }

    /* 3. the searches, when not locked or in doubt */
    if (f->near && f->state != MAR_FOLLOW_PAUSED && !resumed)
        near_search(f, flags);
    if ((f->state == MAR_FOLLOW_SEARCHING || f->state == MAR_FOLLOW_WAITING) && have)
        search_gap(f);
    else
        f->gap_run = 0;
    if (f->searching)
        run_search(f, flags);
    if (f->state == MAR_FOLLOW_SEARCHING) {
        f->conf = 0.0;
        if (!f->ever)
            f->kf.r = 0.0;
    }
}

/* One step with this frame (NULL: none). */
static void step_frame(mar_follow *f, const mar_follow_frame *frame, mar_follow_out *out)
{
    uint32_t flags = 0;
    int have;
    f->c.steps++;
    take_frame(f, frame, &flags, &have);

    if (f->opt.mode == MAR_FOLLOW_MODEL)
        step_model(f, have, &flags);
    else
        step_rules(f, have, &flags);

    /* 4. limits */
    int still = f->state == MAR_FOLLOW_PAUSED || f->state == MAR_FOLLOW_WAITING;
    if (f->opt.mode != MAR_FOLLOW_PAPER && !still && f->ever) {
        if (f->kf.r < f->opt.rate_min)
            f->kf.r = f->opt.rate_min, flags |= MAR_FOLLOW_F_RATE_LIMIT;
        if (f->kf.r > f->opt.rate_max)
            f->kf.r = f->opt.rate_max, flags |= MAR_FOLLOW_F_RATE_LIMIT;
    }
    if (f->kf.p < 0.0)
        f->kf.p = 0.0;
    if (f->kf.p >= (double)f->n) {
        f->kf.p = (double)f->n;
        flags |= MAR_FOLLOW_F_END;
    }
    f->lpos[ring(f, f->t)] = f->kf.p;

    double rate = still ? 0.0 : f->kf.r;
    double ahead = f->kf.p + rate * f->tk.latency;
    out->position = ahead > (double)f->n ? (double)f->n : ahead;
    out->rate = rate;
    out->confidence = f->conf < 0.0 ? 0.0 : f->conf > 1.0 ? 1.0 : f->conf;
    out->state = f->state;
    out->flags = flags;
    f->last = *out;
    f->t++;
}

#define MAX_CATCH_UP 50         /* steps without a frame in one tick, at most (after a long overrun) */

size_t mar_follow_tick(mar_follow *f, const mar_follow_frame *frames, size_t n, int64_t elapsed,
                       mar_follow_out *out)
{
    uint32_t flags = 0;
    mar_follow_out step;
    if (elapsed < 1)
        elapsed = 1;
    if (n > MAR_FOLLOW_TICK_FRAMES)
        n = MAR_FOLLOW_TICK_FRAMES;
    size_t used = 0;
    for (size_t i = 0; i < n; i++) {
        if (!valid_frame(&frames[i])) {
            flags |= MAR_FOLLOW_F_BAD_INPUT;        /* refused as a source would: no step */
            f->c.bad_input++;
            continue;
        }
        step_frame(f, &frames[i], &step);
        flags |= step.flags;
        used++;
    }
    if (used > 0) {
        f->ticks_since_frame = f->unstepped = 0;
    } else {
        f->ticks_since_frame += elapsed;
        f->unstepped += elapsed;
        if (f->ticks_since_frame > MAR_FOLLOW_FRAME_TIMEOUT) {     /* the source is silent: step without */
            for (int64_t k = 0; k < f->unstepped && k < MAX_CATCH_UP; k++) {
                step_frame(f, NULL, &step);
                flags |= step.flags;
            }
            f->unstepped = 0;
        }
    }
    *out = f->last;
    out->position += out->rate * (double)f->unstepped;
    if (out->position > (double)f->n)
        out->position = (double)f->n;
    out->flags = used ? flags : flags | MAR_FOLLOW_F_NO_FRAME;
    return n;
}

void mar_follow_get_counters(const mar_follow *f, mar_follow_counters *c) { *c = f->c; }

size_t mar_follow_stored_length(const mar_follow *f) { return f->n; }
