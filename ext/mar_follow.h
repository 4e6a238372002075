/* Music following: where in the taught music the live music is, every tick.
 *
 * At teach time the music's loudness was stored, one frame per tick (T =
 * 20 ms, marionette/music/feature.py), and its level in a few bands
 * (marionette/music/bands.py; mar_follow_create_music). At the show the same music plays again,
 * maybe faster or slower, wobbling, from anywhere, with pauses. Once per
 * tick the engine hands the newest live loudness frame to mar_follow_step,
 * which answers with the playback position p [stored ticks] and rate r
 * [stored ticks per tick] the show should be played at, a confidence and a
 * state. Two modes:
 *
 *   MAR_FOLLOW_SMOOTH (default): fractional position and rate from the
 *     correlation of live and stored loudness at sub-tick precision, a
 *     Kalman filter for position and rate, confidence gating, a flywheel
 *     through quiet passages, pause detection, and a whole-piece search
 *     (spread over ticks) to start anywhere and to re-acquire a lost lock.
 *   MAR_FOLLOW_PAPER: the paper's tracker (Hoffmann 1996): per tick, double
 *     or skip one stored sample depending on which of the lags -1, 0, +1
 *     correlates best (integer position, rate 0, 1 or 2). It shares the
 *     search and pause handling of the smooth mode, so the two differ only
 *     in how they track.
 *
 * Time: "step t" is the t-th call of mar_follow_step since create (0, 1,
 * ...). The frame passed at a step is the live audio of the tick that just
 * ended, [now - T, now). The position returned is where in the taught
 * music the live music is at "now" (plus opt.latency): stored frame j
 * covers taught time [j T, (j + 1) T), so p = 12.5 means 12.5 T into the
 * taught music. In the engine: p is the show position [show ticks].
 *
 * Plain C11, no Python. The step allocates nothing and never blocks: every
 * buffer is sized in mar_follow_create. Its work is bounded per tick (the
 * search is spread over ticks by opt.search_budget). Status codes: 0 or a
 * negative errno value. One thread per follower. */
#ifndef MAR_FOLLOW_H
#define MAR_FOLLOW_H

#include <stddef.h>
#include <stdint.h>

#include "mar_follow_corr.h"

#define MAR_FOLLOW_MAX_BANDS MAR_CORR_MAX_BANDS     /* band levels per frame, at most */

enum mar_follow_mode {
    MAR_FOLLOW_SMOOTH = 0,          /* fractional position and rate (default) */
    MAR_FOLLOW_PAPER = 1,           /* double or skip one stored sample per tick */
    MAR_FOLLOW_MODEL = 2,           /* smooth tracking, decisions by a model of the tape deck
                                     * (ext/mar_follow_deck.h): experimental, issue 21 */
};

enum mar_follow_state {
    MAR_FOLLOW_SEARCHING = 0,       /* not locked: searching the piece; position is a guess */
    MAR_FOLLOW_LOCKED = 1,          /* following: recent measurements agree */
    MAR_FOLLOW_HOLDING = 2,         /* flywheel: quiet or unclear music, position runs on at the rate */
    MAR_FOLLOW_PAUSED = 3,          /* the recorder stopped: rate 0, position held */
    MAR_FOLLOW_WAITING = 4,         /* at the cue, before the music starts: rate 0 (mar_follow_cue) */
};

/* Flags in mar_follow_out.flags. */
#define MAR_FOLLOW_F_NO_FRAME   1u  /* no live frame this tick (NaN passed) */
#define MAR_FOLLOW_F_BAD_INPUT  2u  /* the frame was negative or infinite: counted, ignored */
#define MAR_FOLLOW_F_MEASURED   4u  /* a correlation measurement corrected the position */
#define MAR_FOLLOW_F_QUIET      8u  /* the live window is too quiet or flat to measure */
#define MAR_FOLLOW_F_JUMP      16u  /* the position jumped (lock, re-lock, resume): blend, don't slew */
#define MAR_FOLLOW_F_SEARCH    32u  /* the whole-piece search ran this tick */
#define MAR_FOLLOW_F_RATE_LIMIT 64u /* the rate hit rate_min or rate_max */
#define MAR_FOLLOW_F_END      128u  /* the position reached the end of the stored music */

/* The follower's options, declared once: X(name, C type, default, lowest,
 * highest, unit, why). The struct, the defaults, the range checks, the
 * table the Python binding reads (mar_follow_option_table), the figure
 * TOML's [follow] keys and the table in docs/music.md all come from this
 * list. Times are in seconds, whatever the tick: mar_follow_create turns
 * them into ticks of opt.tick_period. */
#define MAR_FOLLOW_OPTIONS(X)                                                                        \
    X(mode, int, MAR_FOLLOW_SMOOTH, 0, 2, "",                                                        \
      "smooth: fractional position and rate; paper: double or skip one stored sample per tick; "     \
      "model: smooth, decided by the tape deck model")                                               \
    X(rate_min, double, 0.90, 0.25, 1.0, "1", "slowest playback rate")                              \
    X(rate_max, double, 1.10, 1.0, 4.0, "1", "fastest playback rate")                               \
    X(latency, double, 0.0, 0.0, 10.0, "s",                                                         \
      "from the end of the newest frame's audio to the tick: the answer is p + r * latency")        \
    X(range_db, double, 25.0, 1.0, 200.0, "dB",                                                     \
      "loudness kept below a running peak level; quieter detail, hum and noise read as that")       \
    X(window, double, 4.0, 0.08, 160.0, "s", "tracking correlation window")                         \
    X(min_window, double, 0.8, 0.08, 160.0, "s", "fewest live frames for a tracking measurement")   \
    X(verify_window, double, 5.0, 0.08, 160.0, "s", "window that verifies a search candidate")      \
    X(lock_window, double, 1.0, 0.08, 160.0, "s", "fewest consistent live frames behind a lock")    \
    X(paper_window, double, 0.5, 0.08, 160.0, "s", "paper mode correlation window")                 \
    X(search_block, double, 0.08, 0.02, 1.28, "s", "the search averages the music over blocks this long") \
    X(search_window, double, 2.56, 0.24, 160.0, "s", "live music the search scores a place on")     \
    X(rate_step, double, 0.03, 0.001, 1.0, "1",                                                     \
      "search rate grid step (widened to at most 64 rates over the rate range)")                    \
    X(search_budget, int, 512, 1, 1000000, "1/tick", "search places scored per tick")               \
    X(track_threshold, double, 0.4, 0.0, 0.99, "1", "correlation a tracking measurement needs")    \
    X(lock_threshold, double, 0.6, 0.0, 0.99, "1", "correlation a place needs to lock")            \
    X(lock_margin, double, 0.3, 0.0, 1.9, "Fisher z",                                               \
      "a lock's lead over any other place, at verify_window (more for shorter windows)")           \
    X(hold_after, double, 0.5, 0.0, 3600.0, "s", "no good measurement this long: HOLDING")          \
    X(search_after, double, 0.5, 0.0, 3600.0, "s", "unclear (not quiet) music this long: search beside") \
    X(lost_after, double, 3.0, 0.0, 3600.0, "s", "unclear music this long while HOLDING: SEARCHING") \
    X(quiet_lost_after, double, 30.0, 0.0, 3600.0, "s", "quiet music this long while HOLDING: SEARCHING") \
    X(pause_after, double, 0.16, 0.0, 3600.0, "s",                                                  \
      "silence where music is expected this long (at least a tick): PAUSED")                        \
    X(quiet_db, double, 1.0, 0.0, 100.0, "dB", "a live window whose spread is below this is quiet") \
    X(meas_noise, double, 0.01, 1e-6, 10.0, "s", "tracking measurement noise, 1 sigma")            \
    X(rate_walk, double, 2e-6, 0.0, 1.0, "1/s",                                                     \
      "how fast the rate may wander: its variance grows this much per second")                      \
    X(onset_weight, double, 12.0, 0.0, 100.0, "dB/dB",                                              \
      "with onsets: onset feature = loudness feature + this times the onset strength")              \
    X(stop_every, double, 120.0, 0.1, 1e9, "s", "model: a playing deck stops once in this long, a priori") \
    X(stop_for, double, 3.0, 0.02, 1e9, "s", "model: a stopped deck starts again within this, a priori") \
    X(jump_every, double, 300.0, 0.1, 1e9, "s", "model: the tape jumps once in this long, a priori") \
    X(level_sigma, double, 6.0, 0.1, 100.0, "dB",                                                   \
      "model: a frame's level strays this far from what playing or stopping predicts, 1 sigma")     \
    X(level_cap, double, 2.0, 0.01, 100.0, "1", "model: one frame's evidence on the motion, at most") \
    X(evidence_rate, double, 5.0, 0.01, 1000.0, "1/s",                                              \
      "model: independent values per second and band in a correlation window")                      \
    X(lock_confidence, double, 0.95, 0.5, 0.999999, "1", "model: a place this probable is LOCKED")

typedef struct {
    double tick_period;         /* the follower's step [s]: one stored frame per tick (the engine's own) */
#define MAR_FOLLOW_OPTION_FIELD(name, type, def, lo, hi, unit, why) type name;
    MAR_FOLLOW_OPTIONS(MAR_FOLLOW_OPTION_FIELD)
#undef MAR_FOLLOW_OPTION_FIELD
} mar_follow_options;

/* An option as the Python binding and the docs read it (one entry per X). */
enum mar_follow_option_kind { MAR_FOLLOW_KIND_int = 0, MAR_FOLLOW_KIND_double = 1 };
typedef struct {
    const char *name;
    int kind;                   /* enum mar_follow_option_kind: the field's C type */
    size_t offset;              /* of the field in mar_follow_options [bytes] */
    double default_value, lo, hi;  /* default, lowest and highest allowed (inclusive) */
    const char *unit;           /* "s": a time, turned into ticks at create */
    const char *why;            /* one line */
} mar_follow_option_info;

extern const mar_follow_option_info mar_follow_option_table[];
extern const size_t mar_follow_option_count;

typedef struct {
    double position;            /* where the live music is [stored ticks, fractional] */
    double rate;                /* its speed [stored ticks per tick]; 0 when PAUSED */
    double confidence;          /* [0, 1] */
    int state;                  /* enum mar_follow_state */
    uint32_t flags;             /* MAR_FOLLOW_F_* */
} mar_follow_out;

typedef struct {
    uint64_t steps;             /* mar_follow_step calls */
    uint64_t frames;            /* valid live frames */
    uint64_t missing;           /* steps without a frame (NaN) */
    uint64_t bad_input;         /* negative or infinite frames refused */
    uint64_t measurements;      /* accepted tracking measurements */
    uint64_t rejected;          /* tracking measurements refused (low correlation, gate) */
    uint64_t locks;             /* locks from the search */
    uint64_t pauses;            /* pauses detected */
    uint64_t resumes;           /* resumes after a pause */
    uint64_t search_steps;      /* steps in which the search ran */
} mar_follow_counters;

/* A live frame as a source delivers it. */
typedef struct {
    double loudness;            /* linear [full scale] */
    double onset;               /* onset strength [dB]; NaN: the source has none */
    size_t n_bands;             /* band levels in bands[]; 0: the source measures none */
    double bands[MAR_FOLLOW_MAX_BANDS];     /* linear [full scale] (marionette/music/bands.py) */
} mar_follow_frame;

/* The taught music as the follower takes it: n frames, one per tick. */
typedef struct {
    const double *loudness;     /* n values, linear [full scale], finite and >= 0 */
    const double *onset;        /* n onset strengths [dB], finite and >= 0; NULL: none */
    const double *bands;        /* n rows of n_bands band levels, linear, finite and >= 0; NULL: none */
    size_t n_bands;             /* 1 .. MAR_FOLLOW_MAX_BANDS with bands */
    size_t n;                   /* frames, >= 2 */
} mar_follow_music;

/* mar_follow_tick: frames taken in one tick, at most; ticks without a frame
 * before the follower steps without one (the source may deliver in blocks). */
#define MAR_FOLLOW_TICK_FRAMES 8
#define MAR_FOLLOW_FRAME_TIMEOUT 5

typedef struct mar_follow mar_follow;

/* The defaults of the table, at 20 ms ticks. */
void mar_follow_default_options(mar_follow_options *opt);

/* 0 when the follower takes opt; -EINVAL when not, and *problem (a static
 * string) names the option and the rule: the table's ranges, then the
 * windows in ticks against each other. */
int mar_follow_check_options(const mar_follow_options *opt, const char **problem);

/* Checks opt (mar_follow_check_options, -EINVAL), copies the stored loudness (n_stored frames, one
 * per tick, linear, finite and >= 0: -EINVAL otherwise; n_stored >= 2) and
 * sizes every buffer (-ENOMEM). The follower starts SEARCHING with the
 * whole piece as candidates. Returns NULL on failure and sets *status. */
mar_follow *mar_follow_create(const mar_follow_options *opt, const double *stored, size_t n_stored,
                              int *status);
/* The same, with each stored frame's onset strength (n_stored values,
 * finite and >= 0 [dB]; NULL: none, as mar_follow_create): the tracker then
 * measures the lag of the onset feature (the loudness feature plus
 * opt.onset_weight times the onset) as well as the loudness's (live onsets
 * through mar_follow_step_onset). */
mar_follow *mar_follow_create_onsets(const mar_follow_options *opt, const double *stored,
                                     const double *onset, size_t n_stored, int *status);
/* The same from the music's loudness, onsets and band levels (see
 * mar_follow_music; -EINVAL for a value outside it). With bands, the
 * correlations (tracking, search, cue) run over the bands, each band's
 * mean taken out per window (mar_follow_corr.h), on every window whose
 * newest frame brought as many bands (mar_follow_tick); others, and paper
 * mode, on the loudness. */
mar_follow *mar_follow_create_music(const mar_follow_options *opt, const mar_follow_music *music, int *status);
void mar_follow_destroy(mar_follow *f);

/* One step: one live loudness frame (linear, >= 0), or NaN for a step
 * without one; a negative or infinite value is counted (bad_input), flagged
 * and treated as missing, never used. Fills *out. Never allocates, never
 * blocks, never fails. The engine and the offline tools step through
 * mar_follow_tick, which also runs the clock between frames. */
void mar_follow_step(mar_follow *f, double live, mar_follow_out *out);

/* One step with the live frame's loudness and its onset strength [dB]. A
 * follower made with onsets places the tracking peak on the onset feature
 * where the window has onsets; NaN onset: this frame has none (a source
 * that measures loudness only), the loudness still counts. A follower made
 * without ignores the onset. */
void mar_follow_step_onset(mar_follow *f, double live, double onset, mar_follow_out *out);

/* Known start or seek: the live music is at position [stored ticks] now.
 * The follower plays on from there at rate 1 (state HOLDING) and confirms
 * by correlation; if it cannot, it searches. NaN: unknown, search the whole
 * piece (as after create). The live history is kept. */
void mar_follow_reset(mar_follow *f, double position);

/* The show starts from a cue: the live music will start at `position`
 * [stored ticks] (0: the top). The follower WAITS there (rate 0) through
 * the silence before the music; at the music's onset (a rise out of a
 * steady leader, a note, or music from the first frame) it plays from the first
 * audible stored frame at or after the cue at rate 1 (HOLDING), fits rate
 * and offset jointly on lines through the cue (every 0.1 s for 2 s, then
 * every 0.5 s to 10 s), and LOCKS on two clear fits in a row on the same
 * line that lead every other place of the piece. The tracker alone never
 * makes a pending cue LOCKED; the whole-piece search listens beside it and
 * its lock ends the cue; a cue the music refutes (no fit from 2 s of music
 * on, where the stored music would be heard over hiss) hands over to it.
 * NaN: no cue, search the whole piece (as after create). */
void mar_follow_cue(mar_follow *f, double position);

/* One tick of the show's clock, the way the engine and every offline tool
 * drive the follower: the n live frames that came since the last tick (in
 * order; only the first MAR_FOLLOW_TICK_FRAMES are used, the caller keeps
 * the rest for the next tick) each make one step. Between frames the
 * position runs on at the rate; after MAR_FOLLOW_FRAME_TIMEOUT ticks
 * without a frame the follower steps without one for every tick since its
 * last step (at most 50 in one tick), then once per tick. A frame with a
 * negative or infinite loudness or onset is counted (bad_input), flagged
 * and dropped. elapsed: periods since the last tick (1, more after an
 * overrun). *out: the position at this tick, the flags of all its steps
 * (MAR_FOLLOW_F_NO_FRAME when no frame came). Returns the number of frames
 * taken from frames[] (used or dropped). */
size_t mar_follow_tick(mar_follow *f, const mar_follow_frame *frames, size_t n, int64_t elapsed,
                       mar_follow_out *out);

void mar_follow_get_counters(const mar_follow *f, mar_follow_counters *c);
size_t mar_follow_stored_length(const mar_follow *f);     /* [stored ticks] */

#endif
