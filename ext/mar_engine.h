/* The tick engine: per tick, sample each axis's taught trajectory ahead by
 * its behaviour model's delay, limit the command, send it, record it.
 *
 * Plain C11, no Python. Status codes: 0 or a negative errno value.
 * Real-time (mar_rtloop.h) and step mode run the same mar_engine_tick. */
#ifndef MAR_ENGINE_H
#define MAR_ENGINE_H

#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "mar_follow.h"
#include "mar_hist.h"
#include "mar_lag.h"
#include "mar_limits.h"
#include "mar_move.h"
#include "mar_ring.h"
#include "mar_sample.h"
#include "mar_sink.h"

/* How far ahead of the music a servo is sent its setpoint. */
enum mar_lead_mode {
    MAR_LEAD_NONE = 0,          /* no compensation: x(t) */
    MAR_LEAD_MEAN_DELAY = 1,    /* the paper: x(t + Td + tau) */
    MAR_LEAD_DEAD_TIME_LAG = 2, /* x(t + Td) + tau * x'(t + Td): inverts dead time + first-order lag */
};

/* What the show does while the music is not followed: the follower is
 * SEARCHING after it had a place (a tick of its in another state). */
enum mar_on_lost {
    MAR_ON_LOST_FLYWHEEL = 0,   /* play on at the follower's position and rate: its flywheel, the last rate */
    MAR_ON_LOST_HOLD = 1,       /* hold the position where following was lost, rate 0, until the
                                 * follower has a place again; then blend there */
};

/* What the tick does when a servo node falls silent (the silent mask of
 * mar_engine_set_node_alarms; the figure's [faults] silent_node). */
enum mar_fault_reaction {
    MAR_FAULT_CONTINUE = 0,     /* play on; the records say so (MAR_FLAG_NODE_SILENT) */
    MAR_FAULT_STOP = 1,         /* every axis to rest at its acceleration limit (the stop ramp), then
                                 * hold; latched: the show does not resume (MAR_FLAG_FAULT_STOP) */
    MAR_FAULT_HOLD = 2,         /* the same ramp, the playback clock waits; when every node answers
                                 * again, a blend back into the show where it stopped (MAR_FLAG_FAULT_HOLD) */
    MAR_FAULT_ESTOP = 3,        /* as STOP in the tick; the host also sends the nodes ESTOP (they latch) */
};

/* One axis: behaviour model, limits, addressing. */
typedef struct {
    mar_limits limits;
    double dead_time;           /* pure delay [s] */
    double time_constant;       /* first-order lag tau [s] */
    double start;               /* command before the first tick [unit]; the figure is assumed there, at rest */
    mar_axis_address address;
} mar_axis;

typedef struct {
    double period;              /* tick period [s] */
    int lead_mode;              /* enum mar_lead_mode */
    int interp;                 /* enum mar_interp */
    size_t record_slots;        /* flight recorder capacity [ticks]; 0 = no recorder */
    size_t loudness_slots;      /* live loudness input capacity [frames] */
    int start_holding;          /* 1: start holding the start pose (mode HOLD), 0: playing the show */
    int follow;                 /* 1: the live music's follower drives position and rate (mar_follow.h) */
    mar_follow_options follow_opt;  /* used when follow is 1 */
    double follow_cue;          /* where the live music starts [show ticks] (mar_follow_cue); NaN: unknown */
    const double *follow_bands; /* the taught band levels (n_ticks rows of follow_n_bands, linear), read
                                 * at create only; NULL: the follower correlates the loudness */
    size_t follow_n_bands;      /* 1 .. MAR_FOLLOW_MAX_BANDS with follow_bands */
    int follow_on_lost;         /* enum mar_on_lost, used when follow is 1 (0: flywheel) */
    int on_silent_node;         /* enum mar_fault_reaction (0: continue) */
    uint64_t max_overruns;      /* this many real-time overruns stop the show (latched); 0: never */
} mar_engine_options;

/* Who drives the commands. */
enum mar_mode {
    MAR_MODE_SHOW = 0,          /* the taught show, the playback clock runs */
    MAR_MODE_MOVE = 1,          /* online moves; the playback clock waits */
    MAR_MODE_HOLD = 2,          /* standing still; the playback clock waits */
};

/* Move requests (mar_engine_request). */
enum mar_request {
    MAR_REQ_GOTO = 1,           /* move to the given pose, then hold; NaN targets: stop where possible */
    MAR_REQ_BLEND = 2,          /* move to the show's pose at the playback position, then play */
    MAR_REQ_STOP = 3,           /* each drive, from its predicted motion, to rest at its acceleration limit
                                 * (the stop ramp), then hold */
};

/* Flags in a record. */
#define MAR_FLAG_LIMITED   1u   /* some axis could not follow its target this tick */
#define MAR_FLAG_END       2u   /* the playback position reached the end of the show */
#define MAR_FLAG_BAD_INPUT 4u   /* a non-finite rate, seek or loudness was refused */
#define MAR_FLAG_MOVING    8u   /* online moves drive the commands */
#define MAR_FLAG_HOLDING  16u   /* the figure holds a pose */
#define MAR_FLAG_UNFOLLOWED 32u /* the music is not followed: the follower searches after it had a place */
#define MAR_FLAG_SOURCE_LOST 64u /* the live music's source was lost (mar_engine_source_lost); latched */
#define MAR_FLAG_NODE_SILENT 128u /* a servo node is silent this tick (the silent mask is not 0) */
#define MAR_FLAG_FAULT_STOP 256u /* a fault stopped the show (a silent node with STOP or ESTOP, or the
                                  * overrun threshold): the stop ramp, then hold; latched to the end */
#define MAR_FLAG_FAULT_HOLD 512u /* the show holds for a silent node (MAR_FAULT_HOLD) until every node answers */
#define MAR_FLAG_OVERRUNS 1024u /* the real-time overruns reached max_overruns (then also FAULT_STOP); latched */
#define MAR_FLAG_LINK_LOST 2048u /* the link is gone (write() failed for good, e.g. EIO: the pty's other end
                                  * closed, a USB adapter unplugged; or mar_sink_set_gone from a sender
                                  * outside the tick): every node counts as silent from the next tick on
                                  * (also MAR_FLAG_NODE_SILENT); latched */
#define MAR_FLAG_STOPPING 4096u /* a stop ramp drives the commands (also MAR_FLAG_MOVING): the drives brake
                                 * at their limits from their predicted motion, and the acceleration
                                 * bound acts on that motion, not on the commands (docs/architecture.md) */

/* A flight-recorder record, followed in memory by n_axes commands [unit]
 * and n_axes excesses [unit]: per axis, the target the limits did not let
 * the command reach minus the command (0 where the limits did not act). */
typedef struct {
    int64_t tick;               /* tick number since start */
    int64_t time_ns;            /* scheduled tick time [ns]: CLOCK_MONOTONIC, or virtual in step mode */
    double position;            /* playback position p [show ticks] */
    double rate;                /* playback rate r [show ticks per tick] */
    double live_loudness;       /* newest live loudness frame taken, NaN when none came */
    double stored_loudness;     /* taught loudness at p */
    double follow_confidence;   /* the follower's confidence [0, 1]; NaN without a follower */
    uint32_t flags;             /* MAR_FLAG_* */
    uint32_t limited_axes;      /* how many axes' commands were limited this tick */
    int32_t follow_state;       /* enum mar_follow_state; -1 without a follower */
    uint32_t node_alarms;       /* bit i: the i-th servo node is silent or faulted (set from Python) */
} mar_record;

typedef struct {
    uint64_t ticks;             /* ticks run */
    uint64_t overruns;          /* deadlines missed (real-time) */
    uint64_t limited;           /* axis-ticks where a limit acted */
    uint64_t bad_input;         /* refused non-finite inputs */
    uint64_t records_dropped;   /* flight recorder full */
    uint64_t loudness_dropped;  /* live loudness input full */
    uint64_t sink_frames, sink_errors, sink_bytes;
} mar_counters;

typedef struct mar_engine mar_engine;

/* Copies axes, show (n_axes rows of n_ticks positions [unit]), loudness
 * (n_ticks values) and onsets (n_ticks onset strengths [dB], or NULL: the
 * follower tracks on the loudness alone). On failure returns NULL and sets
 * *status. */
mar_engine *mar_engine_create(const mar_engine_options *opt, const mar_axis *axes, size_t n_axes,
                              const double *show, size_t n_ticks, const double *loudness,
                              const double *onsets, int *status);
void mar_engine_destroy(mar_engine *e);

/* One tick at time now_ns [ns], elapsed_periods (>= 1) periods after the
 * previous one. Never allocates, never blocks, never fails. */
void mar_engine_tick(mar_engine *e, int64_t now_ns, int64_t elapsed_periods);

/* Step mode: n ticks on a virtual clock (tick k at k * period). -EBUSY while
 * the real-time loop runs. */
int mar_engine_step(mar_engine *e, uint64_t n);

/* Commands from any thread, applied at the start of the next tick. */
int mar_engine_set_rate(mar_engine *e, double rate);      /* [show ticks per tick] */
int mar_engine_seek(mar_engine *e, double position);      /* [show ticks] */
int mar_engine_push_loudness(mar_engine *e, double value);   /* one 20 ms frame, >= 0 */
/* The same with the frame's onset strength [dB] (>= 0; NaN: the source has none) */
int mar_engine_push_frame(mar_engine *e, double value, double onset);
/* The same with the frame's band levels (n_bands values, linear, >= 0;
 * marionette/music/bands.py); -EINVAL for a bad value or more than
 * MAR_FOLLOW_MAX_BANDS. */
int mar_engine_push_bands(mar_engine *e, double value, double onset, const double *bands, size_t n_bands);
/* alarms: bit i, the i-th node is silent or faulted (copied into every
 * record's node_alarms); silent: the nodes among them that are silent. The
 * next tick applies on_silent_node when silent is not 0 (or when the link is
 * gone, mar_sink.gone: MAR_FLAG_LINK_LOST). */
void mar_engine_set_node_alarms(mar_engine *e, uint32_t alarms, uint32_t silent);
/* The live music's source is lost (a sound card's stream failed or went
 * silent). Latched from the next tick to the end: every record carries
 * MAR_FLAG_SOURCE_LOST, and with a follower the music is not followed from
 * then on (MAR_FLAG_UNFOLLOWED, follow_on_lost applies at once: the engine
 * plays on at the last tick's rate, or holds). No later frame clears it. */
void mar_engine_source_lost(mar_engine *e);

/* Ask for a move (enum mar_request); targets [unit] has n_axes values for
 * MAR_REQ_GOTO and is ignored otherwise. synchronized: all axes arrive
 * together. One writer at a time; a newer request replaces one the tick has
 * not taken yet, and a request while moving re-plans from where the figure is. */
int mar_engine_request(mar_engine *e, int kind, const double *targets, int synchronized);

/* Consistent copy of the latest tick (seqlock); commands needs n_axes
 * doubles. -EAGAIN if no tick ran yet. */
int mar_engine_snapshot(const mar_engine *e, mar_record *rec, double *commands);

/* Flight recorder: copy up to max records of mar_engine_record_size bytes. */
size_t mar_engine_record_size(const mar_engine *e);
size_t mar_engine_drain_records(mar_engine *e, void *dst, size_t max);

mar_sink *mar_engine_sink(mar_engine *e);
void mar_engine_counters(const mar_engine *e, mar_counters *c);
const mar_hist *mar_engine_wake_hist(const mar_engine *e);     /* wake latency [ns] */
const mar_hist *mar_engine_compute_hist(const mar_engine *e);  /* tick compute time [ns] */
int64_t mar_engine_period_ns(const mar_engine *e);

/* Used by the real-time loop only. */
_Atomic int *mar_engine_running_flag(mar_engine *e);
void mar_engine_count_overruns(mar_engine *e, uint64_t n);
void mar_engine_note_wake(mar_engine *e, int64_t latency_ns);
void mar_engine_note_compute(mar_engine *e, int64_t compute_ns);

#endif
