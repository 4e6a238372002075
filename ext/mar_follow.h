/* Music following: where in the taught music the live music is, every tick.
 *
 * At teach time the music's loudness was stored, one frame per tick (T =
 * 20 ms, marionette/loudness.py). At the show the same music plays again,
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
 * music the live music is at "now" (plus opt.delay ticks): stored frame j
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

enum mar_follow_mode {
    MAR_FOLLOW_SMOOTH = 0,          /* fractional position and rate (default) */
    MAR_FOLLOW_PAPER = 1,           /* double or skip one stored sample per tick */
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

typedef struct {
    int mode;                   /* enum mar_follow_mode */
    double rate_min, rate_max;  /* playback rate limits [stored ticks per tick], 0 < min <= 1 <= max */
    double delay;               /* from the end of the newest frame's audio to the step [ticks]: output = p + r * delay */
    double range_db;            /* loudness kept below a running peak level [dB]; quieter reads as that */
    size_t window;              /* tracking correlation window [ticks] */
    size_t min_window;          /* fewest live frames for a tracking measurement [ticks] */
    size_t verify_window;       /* search candidate verification window [ticks] */
    size_t lock_window;         /* fewest consistent live frames behind a lock [ticks] */
    size_t paper_window;        /* paper mode correlation window [ticks] */
    size_t coarse;              /* search decimation [ticks per coarse frame] */
    size_t search_window;       /* search window [coarse frames] */
    double rate_step;           /* search rate grid step [stored ticks per tick] */
    size_t search_budget;       /* (offset, rate) search candidates scored per tick [1] */
    double track_threshold;     /* correlation a tracking measurement needs [1] */
    double lock_threshold;      /* correlation a search candidate needs to lock [1] */
    double lock_margin;         /* ... and its lead over any other place [Fisher z = atanh(rho)],
                                 * at verify_window frames; times sqrt(verify_window / frames) below */
    double hold_after;          /* ticks without a good measurement before HOLDING [ticks] */
    double search_after;        /* unclear (not quiet) ticks before the search runs beside [ticks] */
    double lost_after;          /* HOLDING ticks (unclear music) before SEARCHING [ticks] */
    double quiet_lost_after;    /* HOLDING ticks (quiet music) before SEARCHING [ticks] */
    double pause_after;         /* silent ticks where music is expected before PAUSED [ticks] */
    double quiet_db;            /* live window spread below this is quiet [dB] */
    double meas_noise;          /* tracking measurement noise, 1 sigma [stored ticks] */
    double rate_noise;          /* rate random walk per tick, 1 sigma [stored ticks per tick] */
    double onset_weight;        /* with onsets: onset feature = feature + this times onset strength [dB/dB] */
} mar_follow_options;

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
} mar_follow_frame;

/* mar_follow_tick: frames taken in one tick, at most; ticks without a frame
 * before the follower steps without one (the source may deliver in blocks). */
#define MAR_FOLLOW_TICK_FRAMES 8
#define MAR_FOLLOW_FRAME_TIMEOUT 5

typedef struct mar_follow mar_follow;

/* Defaults that work for music at 20 ms ticks (see mar_follow.c). */
void mar_follow_default_options(mar_follow_options *opt);

/* Checks opt (-EINVAL), copies the stored loudness (n_stored frames, one
 * per tick, linear, finite and >= 0: -EINVAL otherwise; n_stored >= 2) and
 * sizes every buffer (-ENOMEM). The follower starts SEARCHING with the
 * whole piece as candidates. Returns NULL on failure and sets *status. */
mar_follow *mar_follow_create(const mar_follow_options *opt, const double *stored, size_t n_stored,
                              int *status);
/* The same, with each stored frame's onset strength (n_stored values,
 * finite and >= 0 [dB]; NULL: none, as mar_follow_create): the tracker then
 * places its peak on the onset feature, the loudness feature plus
 * opt.onset_weight times the onset (live onsets through mar_follow_step_onset). */
mar_follow *mar_follow_create_onsets(const mar_follow_options *opt, const double *stored,
                                     const double *onset, size_t n_stored, int *status);
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
 * its lock ends the cue; a cue the music refutes (no fit after 2 s) hands
 * over to it. NaN: no cue, search the whole piece (as after create). */
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
