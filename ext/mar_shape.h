/* Offline pragmatic filter (Hoffmann 1996, section 6): the points of rest of
 * an axis's taught trajectory (its extrema) are joined by timed parabolic
 * moves -- accelerate, cruise, decelerate -- so that each extremum is reached
 * exactly at its taught tick, at rest, without exceeding the servo's top
 * speed and acceleration.
 *
 * Units: positions [unit] (m or rad), times [s], ticks [tick] (index of a
 * show sample), speeds [unit/s], accelerations [unit/s^2].
 *
 * Plain C11; no allocation: every buffer is the caller's. Status codes:
 * 0 or a positive count on success, a negative errno on error.
 * The method, the profile choice and the policies are in docs/shaping.md. */
#ifndef MAR_SHAPE_H
#define MAR_SHAPE_H

#include <stddef.h>
#include <stdint.h>

/* mar_shape_plan: the move does not fit its duration (not an error) */
#define MAR_SHAPE_INFEASIBLE 1

/* What to do with a move that cannot cover its distance in its time. */
typedef enum {
    MAR_SHAPE_REDUCE = 0,   /* move the target toward the start until it fits */
    MAR_SHAPE_BORROW = 1,   /* leave the previous point of rest earlier (within its
                               rest interval); if still short, reduce */
    MAR_SHAPE_REJECT = 2    /* report; the caller fails (planned as REDUCE) */
} mar_shape_policy;

/* mar_shape_segment.action bits */
#define MAR_SHAPE_ACT_REDUCED  1   /* the target was moved toward the start */
#define MAR_SHAPE_ACT_BORROWED 2   /* the move left its point of rest early */
#define MAR_SHAPE_ACT_REJECTED 4   /* infeasible under MAR_SHAPE_REJECT */

/* mar_shape_profile.open bits: an end at a climax where the figure turns
 * without stopping its acceleration (the neighbouring move shares it) */
#define MAR_SHAPE_OPEN_START 1
#define MAR_SHAPE_OPEN_END   2

/* One move: x(t0) = x0, x(t0 + duration) = x1, velocity 0 at both ends.
 * Its core is a parabolic move: a ramp of constant acceleration accel
 * [unit/s^2] of length ramp [s], constant speed peak_speed [unit/s], a ramp
 * of constant deceleration accel_end of length ramp_end (none between them
 * when the ramps fill the core: a triangle). With smooth > 0 the move is the
 * moving average of the core over a window of smooth [s]: the acceleration
 * then changes at a finite jerk, so the engine's lag feed-forward (command =
 * x + lag * x') has no step in velocity (docs/shaping.md).
 * A closed end (at rest) has acceleration 0: the core starts smooth/2 after
 * t0 (ends smooth/2 before the arrival), at rest. An open end
 * (MAR_SHAPE_OPEN_*) is a turn: there the move has velocity 0 and the
 * acceleration turn (turn_end), which the neighbouring move shares, so the
 * climax is the vertex of a parabola, not a flat top. The core reaches that
 * end: its first (last) smooth/2 is that parabola, joined to the cruise by
 * the ramp at accel (accel_end) >= turn (turn_end) from speed turn * smooth/2;
 * beyond the end it goes on as the parabola. It starts (ends)
 * turn * smooth^2 / 24 beyond x0 (x1), the moving average's shift of a
 * parabola, so that the move is at x0 (x1) there. */
typedef struct {
    double t0;          /* departure [s], from the first tick of the show */
    double duration;    /* T [s], > 0 */
    double x0;          /* start position [unit] */
    double x1;          /* end position [unit] */
    double accel;       /* magnitude of the core's first ramp's acceleration [unit/s^2] */
    double peak_speed;  /* magnitude of the core's cruise speed [unit/s] */
    double ramp;        /* length of the core's first ramp [s] (an open start's turn not counted) */
    double smooth;      /* width of the moving average [s], 0 <= smooth < duration */
    double accel_end;   /* magnitude of the core's last ramp's deceleration [unit/s^2] */
    double ramp_end;    /* length of the core's last ramp [s] (an open end's turn not counted) */
    double turn;        /* magnitude of the acceleration at an open start [unit/s^2],
                           <= accel; 0 when closed */
    double turn_end;    /* ... at an open end [unit/s^2], <= accel_end; 0 when closed */
    int32_t open;       /* MAR_SHAPE_OPEN_* bits; 0: rest to rest */
    int32_t reserved;   /* 0 */
} mar_shape_profile;

/* A point of rest: an extremum of the taught trajectory, or an end. */
typedef struct {
    int64_t tick;       /* the climax: tick of the extremum [tick] */
    int64_t rest_end;   /* last tick of its rest [tick], >= tick (see below) */
    double value;       /* taught position there [unit] */
    int32_t kind;       /* +1 maximum, -1 minimum, 0 first or last sample */
    int32_t reserved;   /* 0 */
} mar_shape_extremum;

/* The move from one point of rest to the next. */
typedef struct {
    int64_t from_tick;    /* climax tick of the start point [tick] */
    int64_t depart_tick;  /* tick the move leaves [tick], from_tick..rest_end */
    int64_t arrive_tick;  /* climax tick of the end point [tick] */
    double target;        /* taught end position [unit] */
    double shortfall;     /* |D| - reachable |D| over the nominal window
                             [unit]; 0 when the move fits */
    double reduced_by;    /* |taught target - planned end| [unit] */
    int32_t action;       /* MAR_SHAPE_ACT_* bits; 0 when the move fits */
    int32_t reserved;     /* 0 */
    mar_shape_profile profile;
} mar_shape_segment;

typedef struct {
    double period;          /* tick period [s], > 0 */
    double max_speed;       /* servo top speed vmax [unit/s], > 0 */
    double max_accel;       /* servo top acceleration amax [unit/s^2], > 0 */
    double pos_min;         /* lower position limit [unit] */
    double pos_max;         /* upper position limit [unit] */
    double prominence;      /* smallest counted excursion [unit], > 0 */
    double rest_tolerance;  /* rest band around an extremum [unit], >= 0 */
    int policy;             /* mar_shape_policy */
    double lag;             /* the engine's lag feed-forward tau [s] (command = x + lag * x'),
                               >= 0; 0: the command is the show itself */
    double pos_margin;      /* a move ends at least this far inside [pos_min, pos_max]
                               [unit], >= 0: room for the command's lead over the show */
    int64_t first_depart;   /* the first move leaves no earlier than this tick [tick], >= 0:
                               the command, sampled ahead, starts at rest */
} mar_shape_options;

/* Largest distance |D| [unit] a rest-to-rest move of duration T [s] can
 * cover with |v| <= vmax [unit/s] and |a| <= amax [unit/s^2]:
 *   vmax*T - vmax^2/amax  when T >= 2*vmax/amax (trapezoid at the limits),
 *   amax*T^2/4            otherwise (triangle at amax).
 * 0 for T <= 0; NaN for bad limits. */
double mar_shape_reach(double duration, double max_speed, double max_accel);

/* The limits a move with smoothing window w [s] is planned to, so that its
 * command x + lag * x' keeps |speed| <= vmax and |accel| <= amax: the core
 * cruises at least w between its ramps, so each corner of its acceleration
 * (a step of at most a) becomes on its own a jerk of a/w, which the
 * feed-forward turns into lag * a/w of acceleration: a <= amax * w / (w + lag),
 * and at most vmax / (2 lag). Where the smoothed ramp meets the cruise the
 * command's speed exceeds the core's by at most a * lag^2 / (2w) (lag <= w)
 * or a * (lag - w/2): the speed is vmax less that. lag = 0: vmax and amax. */
void mar_shape_lag_limits(double smooth, double lag, double max_speed, double max_accel,
                          double *speed, double *accel);

/* Largest distance [unit] a rest-to-rest move of duration T [s] covers when
 * its command x + lag * x' must keep the limits: the best over the
 * smoothing width w (written to *smooth [s] when not NULL) of a core of
 * T - w at mar_shape_lag_limits(w) that cruises at least w. lag = 0:
 * mar_shape_reach, smooth 0. NaN for bad limits. */
double mar_shape_reach_lag(double duration, double max_speed, double max_accel, double lag,
                           double *smooth);

/* Shortest duration [s] of a rest-to-rest move over |distance| [unit]
 * (the inverse of mar_shape_reach). NaN for bad limits. */
double mar_shape_min_time(double distance, double max_speed, double max_accel);

/* The move from x0 to x1 [unit] leaving at t0 [s] and arriving duration [s]
 * later, with the least peak acceleration: a triangle, accel = 4|D|/T^2,
 * when its peak speed 2|D|/T <= vmax; else a trapezoid cruising at vmax,
 * accel = vmax^2/(vmax*T - |D|). Returns 0 with *p set when it fits
 * (accel <= amax, peak_speed <= vmax), MAR_SHAPE_INFEASIBLE with *p
 * untouched when |D| > mar_shape_reach(T), -EINVAL for bad arguments
 * (non-finite, duration <= 0, limits <= 0). */
int mar_shape_plan(double x0, double x1, double t0, double duration,
                   double max_speed, double max_accel, mar_shape_profile *p);

/* The same move for a lag feed-forward of lag [s]: the narrowest smoothing
 * width (of those mar_shape_reach_lag tries) with which it fits, and the
 * least-acceleration core that cruises at least that width, to the limits
 * of mar_shape_lag_limits. lag = 0: mar_shape_plan. */
int mar_shape_plan_lag(double x0, double x1, double t0, double duration,
                       double max_speed, double max_accel, double lag, mar_shape_profile *p);

/* The move of mar_shape_plan_lag with smoothing width smooth [s] and the
 * ends of open (MAR_SHAPE_OPEN_* bits): an open end turns with the
 * acceleration turn_start (turn_end) [unit/s^2], > 0, over its core's first
 * (last) smooth/2; its ramp's acceleration is the first that fits of a few
 * from the turn's up to the limit (with smooth 0: the turn's). A closed end's
 * is the first that fits of the open end's ramp's, the limit and halves of the
 * limit. The ramps, the cruise and the accelerations keep the limits of
 * mar_shape_lag_limits(smooth); the cruise lasts at least smooth. Returns 0
 * with *p set, MAR_SHAPE_INFEASIBLE (*p untouched) when no such move fits,
 * -EINVAL for bad arguments. */
int mar_shape_plan_open(double x0, double x1, double t0, double duration,
                        double max_speed, double max_accel, double lag, double smooth,
                        int open, double turn_start, double turn_end, mar_shape_profile *p);

/* Position [unit], velocity [unit/s] and acceleration [unit/s^2] of a move
 * at time t [s] (x0 before t0, x1 after t0 + duration, velocity and
 * acceleration 0 outside the move, and at its ends the acceleration of an
 * open end's turn; the position never leaves [min(x0, x1), max(x0, x1)]).
 * Any output pointer may be NULL. */
void mar_shape_eval(const mar_shape_profile *p, double t,
                    double *x, double *v, double *a);

/* Points of rest of x[0..n) [unit] (the first and last samples are always
 * points of rest), by hysteresis: a maximum counts once the trajectory has
 * risen by >= prominence [unit] to it from the lowest point since the
 * previous point of rest and then fallen by >= prominence after it (minima
 * mirrored); the last pending candidate counts when the show ends. On a
 * plateau the first tick of the extremum is the climax. rest_end is the
 * last tick of the run after the climax where |x - value| <= rest_tolerance
 * [unit], capped before the next point of rest; when the next point of
 * rest itself lies within the tolerance, rest_end = tick (no hold).
 * Writes at most cap entries (cap = n always suffices) and the count to
 * *count. Returns 0, -EINVAL for bad arguments or a non-finite x, -ENOSPC
 * when cap is too small. */
int mar_shape_extrema(const double *x, size_t n, double prominence, double rest_tolerance,
                      mar_shape_extremum *out, size_t cap, size_t *count);

/* Shape one axis: points of rest (mar_shape_extrema), then per pair of
 * consecutive points a move leaving at the end of the first point's rest
 * (the figure holds the taught rest; the first move not before
 * opt->first_depart) and arriving at the second point's climax tick, at
 * rest, planned by mar_shape_plan_lag with opt->lag. Then, from the first
 * climax to the last, at every climax without a rest where the figure
 * turns, the two moves share an acceleration (mar_shape_plan_open): the
 * largest of a few, from the larger of theirs down to the smaller, with
 * which both fit, each move in its own window or a narrower one; the
 * climax is then sharp. Where none fits, it stays at rest (flat). A move's
 * end is kept opt->pos_margin inside the position limits (reported as
 * reduced). An infeasible move is handled by opt->policy and always
 * reported in its segment. out[0..n) receives the shaped trajectory
 * at every tick [unit]. Buffers: ext and seg of at least n entries each
 * (n - 1 segments at most). Returns the number of infeasible segments
 * (>= 0; under MAR_SHAPE_REJECT the output is planned as under REDUCE and
 * the caller must fail when the count is not 0), -EINVAL for bad options
 * or a non-finite x, -ERANGE when a point of rest lies outside
 * [pos_min, pos_max], -ENOSPC when a buffer is too small. */
int mar_shape_axis(const mar_shape_options *opt, const double *x, size_t n,
                   mar_shape_extremum *ext, size_t ext_cap, size_t *n_ext,
                   mar_shape_segment *seg, size_t seg_cap, size_t *n_seg,
                   double *out);

#endif
