#include "mar_engine.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "mar_clock.h"
#include "mar_time.h"


struct mar_engine {
    mar_engine_options opt;
    size_t n_axes, n_ticks;
    int64_t period_ns;              /* [ns] */
    mar_axis *axes;                 /* n_axes */
    double *show;                   /* n_axes rows of n_ticks positions [unit] */
    double *loudness;               /* n_ticks taught loudness */
    double *lead_s;                 /* per axis: how far ahead to sample [s] */
    double *feed_forward;           /* per axis: lag inversion gain tau [s], 0 if off */
    double *cmd;                    /* last command per axis [unit] */
    double *vel;                    /* its velocity [unit/s] */
    double *excess;                 /* per axis: target - command where the limits acted, else 0 [unit] */
    mar_lag *drive;                 /* per axis: the drive's predicted motion when this tick's command
                                     * takes effect (its lag applied to the commands sent) */

    /* tick thread only */
    double position;                /* p [show ticks] */
    double rate;                    /* r [show ticks per tick] */
    mar_follow *follow;             /* NULL: the rate drives the playback clock */
    mar_follow_out follow_out;      /* this tick's answer (mar_follow_tick: flags of all its steps) */
    int had_place;                  /* a tick ended with the follower not SEARCHING: it knew a place */
    int unfollowed;                 /* this tick: SEARCHING after it had a place, or the source
                                     * lost (MAR_FLAG_UNFOLLOWED) */
    int rejoin;                     /* this tick: following again after a hold (MAR_ON_LOST_HOLD),
                                     * or a seek after the source was lost: blend there */
    int source_lost;                /* latched: the live source was lost (MAR_FLAG_SOURCE_LOST) */
    double held_at;                 /* on hold: the position when following was lost [show ticks] */
    mar_clock clock;                /* following: where the show is sampled, following the music's
                                     * position and rate smoothly (mar_clock.h) */
    uint32_t fault;                 /* latched MAR_FLAG_FAULT_STOP | MAR_FLAG_OVERRUNS, or
                                     * MAR_FLAG_FAULT_HOLD while held for a silent node */
    int64_t tick;
    uint64_t bad_input_seen;        /* bad_input at the previous tick */
    int mode;                       /* enum mar_mode */
    int was_playing;                /* the previous tick played the show */
    int move_kind;                  /* enum mar_request being carried out */
    int move_sync;                  /* ... its axes arrive together */
    int move_replans;               /* a GOTO planned again from where its commands ended */
    double move_time;               /* time since the moves were planned [s] */
    double move_duration;           /* longest of them [s] */
    mar_move *moves;                /* per axis */
    uint32_t request_seen;          /* sequence number of the last request taken */
    double *request_copy;           /* the tick's copy of the request targets */

    /* move request mailbox: a seqlock written by one Python thread */
    _Atomic uint32_t request_seq;
    _Atomic int request_kind;
    _Atomic int request_sync;
    double *request_targets;

    /* requests from other threads */
    _Atomic double rate_request;
    _Atomic double seek_request;
    _Atomic int seek_pending;
    _Atomic int source_lost_request;    /* set once by mar_engine_source_lost, never cleared */

    _Atomic uint64_t ticks, overruns, limited, bad_input;
    _Atomic uint32_t node_alarms;
    _Atomic uint32_t silent_nodes;
    _Atomic int running;            /* real-time loop owns the tick */

    mar_ring records;               /* flight recorder */
    mar_ring loudness_in;           /* live loudness from Python */
    mar_sink sink;

    /* seqlock-protected copy of the latest tick */
    _Atomic uint32_t snap_seq;
    mar_record snap;
    double *snap_cmd;

    mar_hist wake;                  /* wake latency [ns] */
    mar_hist compute;               /* tick compute time [ns] */
};

static int check_axis(const mar_axis *a)
{
    const mar_limits *l = &a->limits;
    if (!(l->pos_min <= l->pos_max) || !(l->max_speed > 0.0) || !(l->max_accel > 0.0))
        return -EINVAL;
    if (!(a->dead_time >= 0.0) || !(a->time_constant >= 0.0))
        return -EINVAL;
    if (!(a->start >= l->pos_min && a->start <= l->pos_max))
        return -ERANGE;
    if (!isfinite(l->pos_min) || !isfinite(l->pos_max) || !isfinite(a->dead_time) || !isfinite(a->time_constant))
        return -EINVAL;
    return 0;
}

typedef mar_follow_frame live_frame;    /* as it waits in the input ring */

mar_engine *mar_engine_create(const mar_engine_options *opt, const mar_axis *axes, size_t n_axes,
                              const double *show, size_t n_ticks, const double *loudness,
                              const double *onsets, int *status)
{
    *status = -EINVAL;
    if (n_axes == 0 || n_ticks == 0 || !(opt->period > 0.0) || opt->period > 10.0)
        return NULL;
    if (opt->lead_mode < MAR_LEAD_NONE || opt->lead_mode > MAR_LEAD_DEAD_TIME_LAG)
        return NULL;
    if (opt->interp != MAR_INTERP_LINEAR && opt->interp != MAR_INTERP_CUBIC)
        return NULL;
    if (opt->follow && opt->follow_on_lost != MAR_ON_LOST_FLYWHEEL && opt->follow_on_lost != MAR_ON_LOST_HOLD)
        return NULL;
    if (opt->on_silent_node < MAR_FAULT_CONTINUE || opt->on_silent_node > MAR_FAULT_ESTOP)
        return NULL;
    for (size_t j = 0; j < n_axes; j++) {
        int r = check_axis(&axes[j]);
        if (r < 0) {
            *status = r;
            return NULL;
        }
    }
    for (size_t i = 0; i < n_axes * n_ticks; i++)
        if (!isfinite(show[i]))
            return NULL;

    *status = -ENOMEM;
    mar_engine *e = calloc(1, sizeof *e);
    if (!e)
        return NULL;
    e->opt = *opt;
    e->n_axes = n_axes;
    e->n_ticks = n_ticks;
    e->period_ns = (int64_t)llround(opt->period * 1e9);
    e->axes = malloc(n_axes * sizeof *e->axes);
    e->show = malloc(n_axes * n_ticks * sizeof *e->show);
    e->loudness = malloc(n_ticks * sizeof *e->loudness);
    e->lead_s = malloc(n_axes * sizeof(double));
    e->feed_forward = malloc(n_axes * sizeof(double));
    e->cmd = malloc(n_axes * sizeof(double));
    e->vel = calloc(n_axes, sizeof(double));
    e->excess = calloc(n_axes, sizeof(double));
    e->drive = calloc(n_axes, sizeof *e->drive);
    e->snap_cmd = calloc(n_axes, sizeof(double));
    e->moves = calloc(n_axes, sizeof *e->moves);
    e->request_copy = calloc(n_axes, sizeof(double));
    e->request_targets = calloc(n_axes, sizeof(double));
    mar_axis_address *addr = malloc(n_axes * sizeof *addr);
    int ok = e->axes && e->show && e->loudness && e->lead_s && e->feed_forward && e->cmd
          && e->vel && e->excess && e->drive && e->snap_cmd && e->moves && e->request_copy && e->request_targets && addr;
    if (ok) {
        memcpy(e->axes, axes, n_axes * sizeof *axes);
        memcpy(e->show, show, n_axes * n_ticks * sizeof *show);
        for (size_t i = 0; i < n_ticks; i++)    /* missing loudness reads as NaN */
            e->loudness[i] = loudness ? loudness[i] : NAN;
        for (size_t j = 0; j < n_axes; j++) {
            const mar_axis *a = &axes[j];
            e->lead_s[j] = opt->lead_mode == MAR_LEAD_NONE ? 0.0
                         : opt->lead_mode == MAR_LEAD_MEAN_DELAY ? a->dead_time + a->time_constant
                         : a->dead_time;
            e->feed_forward[j] = opt->lead_mode == MAR_LEAD_DEAD_TIME_LAG ? a->time_constant : 0.0;
            e->cmd[j] = a->start;
            /* the lag the lead inverts (none: the drive is taken to follow its command) */
            e->drive[j] = (mar_lag){.tau = e->feed_forward[j], .vmax = a->limits.max_speed,
                                    .period = opt->period, .y = a->start, .v = 0.0};
            addr[j] = a->address;
        }
        *status = mar_sink_init(&e->sink, n_axes, addr);
        ok = *status == 0;
    }
    free(addr);
    if (ok && opt->record_slots > 0)
        ok = (*status = mar_ring_init(&e->records, mar_engine_record_size(e), opt->record_slots)) == 0;
    if (ok)
        ok = (*status = mar_ring_init(&e->loudness_in, sizeof(live_frame), opt->loudness_slots)) == 0;
    if (ok && opt->follow) {    /* refuses a show without finite, non-negative loudness (and onsets) */
        mar_follow_options follow_opt = opt->follow_opt;
        follow_opt.tick_period = opt->period;       /* the follower steps at the engine's tick */
        const mar_follow_music music = {.loudness = e->loudness, .onset = onsets, .bands = opt->follow_bands,
                                        .n_bands = opt->follow_n_bands, .n = n_ticks};
        ok = (e->follow = mar_follow_create_music(&follow_opt, &music, status)) != NULL;
    }
    if (!ok) {
        mar_engine_destroy(e);
        return NULL;
    }
    e->rate = 1.0;
    if (e->follow) {            /* the show waits at the cue for the music */
        mar_follow_cue(e->follow, opt->follow_cue);
        if (isfinite(opt->follow_cue))
            e->position = fmin(fmax(opt->follow_cue, 0.0), (double)(n_ticks - 1));
    }
    e->mode = opt->start_holding ? MAR_MODE_HOLD : MAR_MODE_SHOW;
    atomic_init(&e->rate_request, 1.0);
    atomic_init(&e->seek_request, 0.0);
    mar_hist_reset(&e->wake);
    mar_hist_reset(&e->compute);
    *status = 0;
    return e;
}

void mar_engine_destroy(mar_engine *e)
{
    if (!e)
        return;
    if (e->records.slots)
        mar_ring_free(&e->records);
    if (e->loudness_in.slots)
        mar_ring_free(&e->loudness_in);
    mar_sink_free(&e->sink);
    mar_follow_destroy(e->follow);
    free(e->axes);
    free(e->show);
    free(e->loudness);
    free(e->lead_s);
    free(e->feed_forward);
    free(e->cmd);
    free(e->vel);
    free(e->excess);
    free(e->drive);
    free(e->snap_cmd);
    free(e->moves);
    free(e->request_copy);
    free(e->request_targets);
    free(e);
}

/* Without a follower: the newest live loudness frame, NaN when none
 * came; older ones are dropped. */
static double newest_live_loudness(mar_engine *e)
{
    live_frame frames[16];
    double newest = NAN;
    size_t n;
    while ((n = mar_ring_pop(&e->loudness_in, frames, 16)) > 0)
        newest = frames[n - 1].loudness;
    return newest;
}

/* The playback clock from the live music: the follower's own tick
 * (mar_follow_tick) on the frames that came, as every offline tool runs it.
 * Frames beyond MAR_FOLLOW_TICK_FRAMES wait in the ring for the next tick,
 * so a burst drains instead of adding latency. Returns the newest frame
 * taken, NaN if none.
 *
 * The music is not followed while the follower searches after it had a
 * place. Its own position then runs on at its last rate (its flywheel; from
 * an unknown start it has no place and stands still at rate 0). With
 * MAR_ON_LOST_HOLD the show does not play on: the position stays where the
 * previous tick had it, rate 0, and when the follower has a place again the
 * tick blends there (e->rejoin), whether or not it flagged a jump.
 *
 * Once the source is lost (e->source_lost, latched) the music is not
 * followed to the end, whatever the follower says: it still steps (on the
 * frames already in the ring, then none) and its state and confidence go
 * into the records, but its position, rate and jumps no longer drive the
 * show. The flywheel is then the engine's own: the position runs on at the
 * rate of the previous tick (0 while WAITING at the cue or with no place
 * yet); hold stands as above. A seek still places the show (blended). */
static double follow_music(mar_engine *e, int64_t elapsed_periods, int seek, double seek_to)
{
    mar_follow_frame frames[MAR_FOLLOW_TICK_FRAMES];
    if (seek)
        mar_follow_reset(e->follow, seek_to);
    size_t n = mar_ring_pop(&e->loudness_in, frames, MAR_FOLLOW_TICK_FRAMES);
    mar_follow_tick(e->follow, frames, n, elapsed_periods, &e->follow_out);
    int hold = e->opt.follow_on_lost == MAR_ON_LOST_HOLD;
    int was_unfollowed = e->unfollowed;
    int searching = e->follow_out.state == MAR_FOLLOW_SEARCHING;
    int unfollowed = e->source_lost || (searching && e->had_place);
    if (unfollowed && !was_unfollowed)
        e->held_at = e->position;       /* the last followed tick's position */
    e->unfollowed = unfollowed;
    e->rejoin = hold && was_unfollowed && !unfollowed;
    if (!searching)
        e->had_place = 1;
    if (e->source_lost && seek) {       /* the operator places the show: blend there */
        e->held_at = seek_to;
        e->rejoin = 1;
    }
    if (hold && e->unfollowed) {
        e->position = e->held_at;
        e->rate = 0.0;
    } else if (e->source_lost) {        /* the engine's flywheel at the previous tick's rate */
        e->position = seek ? seek_to : e->position + e->rate * (double)elapsed_periods;
    } else {
        e->position = e->follow_out.position;
        e->rate = e->follow_out.rate;
    }
    return n > 0 ? frames[n - 1].loudness : NAN;
}

static void publish_snapshot(mar_engine *e, const mar_record *rec)
{
    uint32_t seq = atomic_load_explicit(&e->snap_seq, memory_order_relaxed);
    atomic_store_explicit(&e->snap_seq, seq + 1, memory_order_relaxed);
    atomic_thread_fence(memory_order_release);
    e->snap = *rec;
    memcpy(e->snap_cmd, e->cmd, e->n_axes * sizeof(double));
    atomic_store_explicit(&e->snap_seq, seq + 2, memory_order_release);
}

/* Where axis j should be for playback position p at rate r: the show
 * sampled ahead by the axis's lead, plus the lag feed-forward. */
static double show_target(const mar_engine *e, size_t j, double p, double r)
{
    const double T = e->opt.period;
    double slope;                                       /* [unit/show tick] */
    double ahead = p + r * e->lead_s[j] / T;            /* [show ticks] */
    double x = mar_sample(e->show + j * e->n_ticks, e->n_ticks, ahead, e->opt.interp, &slope);
    return x + e->feed_forward[j] * slope * r / T;
}

/* Online moves are planned this far inside the limits [1]: a move at the
 * limits, sampled, asks the limiter for exactly its bound, and rounding
 * then counted ticks of a stop ramp as limited (by 1e-16). */
#define MOVE_INSIDE (1.0 - 1e-9)

/* A GOTO whose commands the limiter held back (near a position limit the
 * sampled braking bound is tighter than the profile's) is planned again
 * from where they ended, at most this many times [1] */
#define GOTO_REPLANS 4

/* The servos' motion when this tick's command takes effect: the previous
 * command, held for elapsed_periods, moved each lag (its dead time only
 * shifts it in time). */
static void predict_motion(mar_engine *e, int64_t elapsed_periods)
{
    for (size_t j = 0; j < e->n_axes; j++)
        mar_lag_hold(&e->drive[j], e->cmd[j], elapsed_periods);
}

/* Plan every axis's move: to the request's pose (GOTO) or to the show's
 * pose at blend_position [show ticks] (BLEND) from its present command and
 * velocity, sync: all arrive together; or to rest (STOP): the servo's
 * predicted motion brakes at the acceleration limit, and the commands
 * (stop_target) invert the lag to make it do so. */
static void plan_moves(mar_engine *e, int kind, int sync, double blend_position)
{
    double longest = 0.0;
    for (size_t j = 0; j < e->n_axes; j++) {
        const mar_limits *l = &e->axes[j].limits;
        int stop = kind == MAR_REQ_STOP;
        double x0 = stop ? e->drive[j].y : e->cmd[j], v0 = stop ? e->drive[j].v : e->vel[j];
        /* a lag's drive brakes 3/4 amax*T in each of the first two ticks, not
         * 1/2 then 1: at top speed, where its motion within a tick changes
         * shape as it slows, that is what its limit allows (Stops) */
        if (stop && v0 != 0.0 && e->drive[j].tau > 0.0)
            x0 -= (v0 > 0.0 ? 0.25 : -0.25) * l->max_accel * e->opt.period * e->opt.period;
        double target = kind == MAR_REQ_BLEND ? show_target(e, j, blend_position, e->rate)
                      : kind == MAR_REQ_GOTO ? e->request_copy[j] : NAN;
        if (!isfinite(target))                          /* stop where braking ends */
            target = x0 + v0 * fabs(v0) / (2.0 * l->max_accel * MOVE_INSIDE);
        target = target < l->pos_min ? l->pos_min : target > l->pos_max ? l->pos_max : target;
        double d = mar_move_plan(&e->moves[j], x0, v0, target, l->max_speed * MOVE_INSIDE,
                                 l->max_accel * MOVE_INSIDE);
        if (d > longest)
            longest = d;
    }
    if (sync && kind != MAR_REQ_STOP) {                 /* stretch the others to the longest */
        for (size_t j = 0; j < e->n_axes; j++) {
            const mar_limits *l = &e->axes[j].limits;
            mar_move *m = &e->moves[j];
            mar_move_plan_timed(m, m->x0, m->v0, m->target, l->max_speed * MOVE_INSIDE,
                                l->max_accel * MOVE_INSIDE, longest);
        }
    }
    e->mode = MAR_MODE_MOVE;
    e->move_kind = kind;
    e->move_sync = sync;
    e->move_time = 0.0;
    /* a stop's commands lead its profile by a tick (stop_target): they
     * reach rest one tick after it, and their velocity 0 one tick later */
    e->move_duration = kind == MAR_REQ_STOP ? longest + 2.0 * e->opt.period : longest;
}

/* Every command stands on its move's target. */
static int at_targets(const mar_engine *e)
{
    for (size_t j = 0; j < e->n_axes; j++)
        if (e->cmd[j] != e->moves[j].target)
            return 0;
    return 1;
}

/* Axis j's target in mode MOVE at move_time t [s]: the profile. */
static double move_target(const mar_engine *e, size_t j, double t)
{
    double v;
    return mar_move_eval(&e->moves[j], t, &v);
}

/* Axis j's command in a stop: the input that moves the drive from where it
 * will be to the profile at move_time t [s], if its acceleration allows
 * (mar_lag_stop_input), with the command velocities [unit/s] that keep it
 * within the limit (accel). Sets *limited when the profile is left. */
static double stop_target(const mar_engine *e, size_t j, double t, double accel[2], int *limited)
{
    double v, T = e->opt.period, window[2], input;                   /* [unit] */
    double goal = mar_move_eval(&e->moves[j], t, &v), after = mar_move_eval(&e->moves[j], t + T, &v);
    *limited = mar_lag_stop_input(&e->drive[j], e->axes[j].limits.max_accel, goal, after, window, &input);
    accel[0] = (window[0] - e->cmd[j]) / T;
    accel[1] = (window[1] - e->cmd[j]) / T;
    return input;
}

/* The fault reactions, after the operator's request of this tick (a fault
 * overrides it): a silent node (on_silent_node) or the overrun threshold.
 * STOP, ESTOP and the overruns plan the stop ramp once and latch; HOLD
 * plans it when a node falls silent and blends back into the show at the
 * playback position when every node answers again. Returns the fault flags. */
static uint32_t react_to_faults(mar_engine *e, uint32_t silent)
{
    if (e->fault & MAR_FLAG_FAULT_STOP)
        return e->fault;
    uint64_t limit = e->opt.max_overruns;
    int overrun = limit > 0 && atomic_load_explicit(&e->overruns, memory_order_relaxed) >= limit;
    int reaction = e->opt.on_silent_node;
    if (overrun || (silent && (reaction == MAR_FAULT_STOP || reaction == MAR_FAULT_ESTOP))) {
        e->fault = MAR_FLAG_FAULT_STOP | (overrun ? MAR_FLAG_OVERRUNS : 0u);
        plan_moves(e, MAR_REQ_STOP, 0, e->position);
    } else if (reaction == MAR_FAULT_HOLD && silent && !e->fault) {
        e->fault = MAR_FLAG_FAULT_HOLD;
        plan_moves(e, MAR_REQ_STOP, 0, e->position);
    } else if (e->fault == MAR_FLAG_FAULT_HOLD && !silent) {
        e->fault = 0;
        plan_moves(e, MAR_REQ_BLEND, 1, e->position);
    }
    return e->fault;
}

/* Take a new move request, if one came, and plan the moves. */
static void take_request(mar_engine *e)
{
    uint32_t s1 = atomic_load_explicit(&e->request_seq, memory_order_acquire);
    if ((s1 & 1u) || s1 == e->request_seen)
        return;                                         /* none, or being written: next tick */
    int kind = atomic_load_explicit(&e->request_kind, memory_order_relaxed);
    int sync = atomic_load_explicit(&e->request_sync, memory_order_relaxed);
    memcpy(e->request_copy, e->request_targets, e->n_axes * sizeof(double));
    atomic_thread_fence(memory_order_acquire);
    if (atomic_load_explicit(&e->request_seq, memory_order_relaxed) != s1)
        return;                                         /* overwritten meanwhile: next tick */
    e->request_seen = s1;
    e->move_replans = 0;
    plan_moves(e, kind, sync, e->position);
}

void mar_engine_tick(mar_engine *e, int64_t now_ns, int64_t elapsed_periods)
{
    const double T = e->opt.period;
    const double last = (double)(e->n_ticks - 1);
    uint32_t flags = 0;

    /* 1. playback clock: advance by the rate in force since the last tick,
     *    then predict the servos' motion and take requests. Missed periods
     *    still count (real time). The clock waits while moves or a hold
     *    drive the figure. */
    if (!e->source_lost && atomic_load_explicit(&e->source_lost_request, memory_order_acquire))
        e->source_lost = 1;
    int seek = atomic_exchange_explicit(&e->seek_pending, 0, memory_order_acquire);
    double seek_to = atomic_load_explicit(&e->seek_request, memory_order_relaxed);
    double frame;
    if (e->follow) {            /* the music runs on whatever drives the figure */
        frame = follow_music(e, elapsed_periods, seek, seek_to);
    } else {
        frame = newest_live_loudness(e);
        if (e->was_playing)
            e->position += e->rate * (double)elapsed_periods;
        e->rate = atomic_load_explicit(&e->rate_request, memory_order_relaxed);
        if (seek)
            e->position = seek_to;
    }
    if (e->position < 0.0)
        e->position = 0.0;
    if (e->position >= last) {
        e->position = last;
        flags |= MAR_FLAG_END;
    }
    uint64_t bad = atomic_load_explicit(&e->bad_input, memory_order_relaxed);
    if (bad != e->bad_input_seen) {
        e->bad_input_seen = bad;
        flags |= MAR_FLAG_BAD_INPUT;
    }
    predict_motion(e, elapsed_periods);
    take_request(e);
    uint32_t silent = atomic_load_explicit(&e->silent_nodes, memory_order_relaxed);
    if (atomic_load_explicit(&e->sink.gone, memory_order_relaxed)) {
        flags |= MAR_FLAG_LINK_LOST;    /* a write found the link gone: the tick's own, or the sender's */
        silent = ~0u;
    }
    flags |= react_to_faults(e, silent) | (silent ? MAR_FLAG_NODE_SILENT : 0u);
    int jump = (e->follow_out.flags & MAR_FOLLOW_F_JUMP) && !e->source_lost;
    if (e->follow && (jump || e->rejoin) && e->mode == MAR_MODE_SHOW) {
        /* the music's position jumped (lock, re-lock, resume, or the end of
         * a hold while it was not followed): a timed blend to where the
         * music will be when the figure arrives, not a slew */
        plan_moves(e, MAR_REQ_BLEND, 1, e->position);
        double arrive = e->position + e->rate * e->move_duration / T;
        plan_moves(e, MAR_REQ_BLEND, 1, arrive < last ? arrive : last);
    }
    /* a GOTO's profile runs a period per tick: after missed periods its
     * commands go on from where they were, each step within the limits,
     * and reach the pose later (in wall time, the profile ran ahead of
     * the limited commands and the hold stood short of the pose). A stop's
     * profile runs with the drives' time, a blend's with the music's */
    if (e->mode == MAR_MODE_MOVE)
        e->move_time += T * (double)(e->move_kind == MAR_REQ_GOTO ? 1 : elapsed_periods);
    /* following, the show is sampled at a clock that follows the music
     * smoothly while it plays on; moves, holds and seeks set it. The
     * paper's mode doubles and skips samples as the paper did */
    double p = e->position, r = e->rate;
    if (e->follow && e->opt.follow_opt.mode != MAR_FOLLOW_PAPER) {
        if (e->mode == MAR_MODE_SHOW && e->was_playing && !seek)
            mar_clock_follow(&e->clock, p, r, T, e->opt.follow_opt.rate_max - 1.0);
        else
            mar_clock_set(&e->clock, p, r);
        p = e->clock.position < 0.0 ? 0.0 : e->clock.position < last ? e->clock.position : last;
        r = e->clock.rate;
    }

    /* 2. per axis: the show sampled ahead by the behaviour model, or the
     *    move's profile, or the held pose; then the hard limits */
    uint32_t limited = 0;
    int stopping = e->mode == MAR_MODE_MOVE && e->move_kind == MAR_REQ_STOP;
    for (size_t j = 0; j < e->n_axes; j++) {
        double target, accel[2];
        int left = 0, hit;
        if (stopping)
            target = stop_target(e, j, e->move_time, accel, &left);
        else if (e->mode == MAR_MODE_SHOW)
            target = show_target(e, j, p, r);
        else if (e->mode == MAR_MODE_MOVE)
            target = move_target(e, j, e->move_time);
        else
            target = e->cmd[j];
        e->cmd[j] = mar_limit_step(&e->axes[j].limits, T, e->cmd[j], e->vel[j], target,
                                   stopping ? accel : NULL, &e->vel[j], &hit);
        e->excess[j] = hit ? target - e->cmd[j] : 0.0;
        limited += (uint32_t)(hit || left);
    }
    if (limited)
        flags |= MAR_FLAG_LIMITED;
    if (e->follow && e->unfollowed)
        flags |= MAR_FLAG_UNFOLLOWED;
    if (e->source_lost)
        flags |= MAR_FLAG_SOURCE_LOST;
    e->was_playing = e->mode == MAR_MODE_SHOW;
    flags |= e->mode == MAR_MODE_MOVE ? MAR_FLAG_MOVING : e->mode == MAR_MODE_HOLD ? MAR_FLAG_HOLDING : 0u;
    if (stopping)
        flags |= MAR_FLAG_STOPPING;
    if (e->mode == MAR_MODE_MOVE && e->move_time >= e->move_duration) {  /* arrived: next tick */
        if (e->move_kind == MAR_REQ_GOTO && !at_targets(e) && e->move_replans < GOTO_REPLANS) {
            e->move_replans++;
            plan_moves(e, MAR_REQ_GOTO, e->move_sync, e->position);
        } else {
            e->mode = e->move_kind == MAR_REQ_BLEND ? MAR_MODE_SHOW : MAR_MODE_HOLD;
        }
    }

    double slope;
    mar_record rec = {
        .tick = e->tick,
        .time_ns = now_ns,
        .position = e->position,         /* the music's place when following */
        .rate = e->rate,
        .live_loudness = frame,          /* NaN: no new frame this tick */
        .stored_loudness = mar_sample(e->loudness, e->n_ticks, e->position, MAR_INTERP_LINEAR, &slope),
        .follow_confidence = e->follow ? e->follow_out.confidence : NAN,
        .flags = flags,
        .limited_axes = limited,
        .follow_state = e->follow ? e->follow_out.state : -1,
        .node_alarms = atomic_load_explicit(&e->node_alarms, memory_order_relaxed),
    };

    /* 3. out to the servos, 4. flight recorder and snapshot */
    mar_sink_emit(&e->sink, (uint32_t)e->tick, e->cmd);
    uint8_t *slot = e->records.slots ? mar_ring_claim(&e->records) : NULL;
    if (slot) {
        memcpy(slot, &rec, sizeof rec);
        memcpy(slot + sizeof rec, e->cmd, e->n_axes * sizeof(double));
        memcpy(slot + sizeof rec + e->n_axes * sizeof(double), e->excess, e->n_axes * sizeof(double));
        mar_ring_publish(&e->records);
    }
    publish_snapshot(e, &rec);

    e->tick++;
    atomic_fetch_add_explicit(&e->ticks, 1, memory_order_relaxed);
    if (limited)
        atomic_fetch_add_explicit(&e->limited, limited, memory_order_relaxed);
}

int mar_engine_step(mar_engine *e, uint64_t n)
{
    if (atomic_load(&e->running))
        return -EBUSY;
    for (uint64_t i = 0; i < n; i++) {
        int64_t t0 = mar_now_ns();
        mar_engine_tick(e, e->tick * e->period_ns, 1);
        mar_hist_add(&e->compute, mar_now_ns() - t0);
    }
    return 0;
}

int mar_engine_set_rate(mar_engine *e, double rate)
{
    if (!isfinite(rate)) {
        atomic_fetch_add(&e->bad_input, 1);
        return -EINVAL;
    }
    atomic_store_explicit(&e->rate_request, rate, memory_order_relaxed);
    return 0;
}

int mar_engine_seek(mar_engine *e, double position)
{
    if (!isfinite(position)) {
        atomic_fetch_add(&e->bad_input, 1);
        return -EINVAL;
    }
    atomic_store_explicit(&e->seek_request, position, memory_order_relaxed);
    atomic_store_explicit(&e->seek_pending, 1, memory_order_release);
    return 0;
}

int mar_engine_push_loudness(mar_engine *e, double value)
{
    return mar_engine_push_frame(e, value, NAN);
}

int mar_engine_push_frame(mar_engine *e, double value, double onset)
{
    return mar_engine_push_bands(e, value, onset, NULL, 0);
}

int mar_engine_push_bands(mar_engine *e, double value, double onset, const double *bands, size_t n_bands)
{
    live_frame frame = {.loudness = value, .onset = onset, .n_bands = n_bands};
    int ok = isfinite(value) && value >= 0.0 && (isnan(onset) || (isfinite(onset) && onset >= 0.0))
          && n_bands <= MAR_FOLLOW_MAX_BANDS;
    for (size_t b = 0; ok && b < n_bands; b++) {
        frame.bands[b] = bands[b];
        ok = isfinite(bands[b]) && bands[b] >= 0.0;
    }
    if (!ok) {
        atomic_fetch_add(&e->bad_input, 1);
        return -EINVAL;
    }
    return mar_ring_push(&e->loudness_in, &frame, sizeof frame);
}

void mar_engine_set_node_alarms(mar_engine *e, uint32_t alarms, uint32_t silent)
{
    atomic_store_explicit(&e->node_alarms, alarms | silent, memory_order_relaxed);
    atomic_store_explicit(&e->silent_nodes, silent, memory_order_relaxed);
}

void mar_engine_source_lost(mar_engine *e)
{
    atomic_store_explicit(&e->source_lost_request, 1, memory_order_release);
}

int mar_engine_request(mar_engine *e, int kind, const double *targets, int synchronized)
{
    if (kind != MAR_REQ_GOTO && kind != MAR_REQ_BLEND && kind != MAR_REQ_STOP)
        return -EINVAL;
    uint32_t seq = atomic_load_explicit(&e->request_seq, memory_order_relaxed);
    atomic_store_explicit(&e->request_seq, seq + 1, memory_order_relaxed);   /* odd: writing */
    atomic_thread_fence(memory_order_release);
    atomic_store_explicit(&e->request_kind, kind, memory_order_relaxed);
    atomic_store_explicit(&e->request_sync, synchronized != 0, memory_order_relaxed);
    if (kind == MAR_REQ_GOTO)
        memcpy(e->request_targets, targets, e->n_axes * sizeof(double));
    atomic_store_explicit(&e->request_seq, seq + 2, memory_order_release);
    return 0;
}

int mar_engine_snapshot(const mar_engine *e, mar_record *rec, double *commands)
{
    for (int attempt = 0; attempt < 1000; attempt++) {
        uint32_t s1 = atomic_load_explicit(&e->snap_seq, memory_order_acquire);
        if (s1 == 0)
            return -EAGAIN;
        if (s1 & 1u)
            continue;
        *rec = e->snap;
        memcpy(commands, e->snap_cmd, e->n_axes * sizeof(double));
        atomic_thread_fence(memory_order_acquire);
        if (atomic_load_explicit(&e->snap_seq, memory_order_relaxed) == s1)
            return 0;
    }
    return -EBUSY;
}

size_t mar_engine_record_size(const mar_engine *e)
{
    return sizeof(mar_record) + 2 * e->n_axes * sizeof(double);
}

size_t mar_engine_drain_records(mar_engine *e, void *dst, size_t max)
{
    return e->records.slots ? mar_ring_pop(&e->records, dst, max) : 0;
}

mar_sink *mar_engine_sink(mar_engine *e) { return &e->sink; }
const mar_hist *mar_engine_wake_hist(const mar_engine *e) { return &e->wake; }
const mar_hist *mar_engine_compute_hist(const mar_engine *e) { return &e->compute; }
int64_t mar_engine_period_ns(const mar_engine *e) { return e->period_ns; }
_Atomic int *mar_engine_running_flag(mar_engine *e) { return &e->running; }

void mar_engine_counters(const mar_engine *e, mar_counters *c)
{
    c->ticks = atomic_load(&e->ticks);
    c->overruns = atomic_load(&e->overruns);
    c->limited = atomic_load(&e->limited);
    c->bad_input = atomic_load(&e->bad_input);
    c->records_dropped = e->records.slots ? mar_ring_dropped(&e->records) : 0;
    c->loudness_dropped = mar_ring_dropped(&e->loudness_in);
    c->sink_frames = atomic_load(&e->sink.frames);
    c->sink_errors = atomic_load(&e->sink.errors);
    c->sink_bytes = atomic_load(&e->sink.bytes);
}

void mar_engine_count_overruns(mar_engine *e, uint64_t n)
{
    atomic_fetch_add_explicit(&e->overruns, n, memory_order_relaxed);
}

void mar_engine_note_wake(mar_engine *e, int64_t latency_ns) { mar_hist_add(&e->wake, latency_ns); }
void mar_engine_note_compute(mar_engine *e, int64_t compute_ns) { mar_hist_add(&e->compute, compute_ns); }
