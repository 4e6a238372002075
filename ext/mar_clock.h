/* The clock the show is sampled at while the engine follows live music: it
 * follows the music's place (the follower's position and rate) smoothly.
 *
 * The follower corrects its position and rate in steps (a measurement moves
 * the position by a tick or so; the rate changes by a few percent), and a
 * show sampled at such a clock commands steps in speed and, through the lag
 * feed-forward tau * x' * rate, in position: the hard limiter cuts them. This
 * clock's position has a continuous rate and rate change: a critically damped
 * third-order tracker (three poles at -MAR_CLOCK_OMEGA) of the music's
 * position and rate, so it follows a steady rate without lag, and a step of
 * the music's position or rate becomes a smooth change of the show's rate.
 *
 * Far behind or ahead of the music (the music started before the cue heard
 * it), it runs catch_up faster or slower than the music (the engine passes
 * the follower's rate_max - 1: the fastest rate the shaper plans for, at the
 * music's rate 1), and a rate far from the music's is approached at a rate
 * change of about w MAR_CLOCK_RATE_STEP per tick (w = MAR_CLOCK_OMEGA *
 * period). Standing (at rate 0, as at the cue), it starts at the music's
 * rate at once, as a show starts from its first tick. It never runs
 * backwards.
 *
 * Units: positions [show ticks], rates [show ticks per tick], rate changes
 * [show ticks per tick^2]. Plain C11, no allocation. docs/music.md. */
#ifndef MAR_CLOCK_H
#define MAR_CLOCK_H

#define MAR_CLOCK_OMEGA 3.0         /* the tracker's poles [1/s]: a correction of one tick
                                       settles in about 1.5 s, changing the rate by at most
                                       1.6 % and the rate's rate of change by 0.44 /s^2 */
#define MAR_CLOCK_RATE_STEP 0.3     /* a rate error counts as at most this [1] */
#define MAR_CLOCK_MIN_CATCH_UP 0.01 /* the least catch_up [1] */

typedef struct {
    double position;                /* where the show is sampled [show ticks] */
    double rate;                    /* [show ticks per tick] */
    double change;                  /* rate change [show ticks per tick^2] */
} mar_clock;

/* Stand at position at rate, with no change of rate (a jump, a blend, a seek). */
void mar_clock_set(mar_clock *c, double position, double rate);

/* One tick of period [s] towards the music's position and rate; catch_up
 * [1] as above (at least MAR_CLOCK_MIN_CATCH_UP). One tick also after an
 * overrun: the periods it missed (the nodes held their last setpoint) are
 * caught up like a far music, not jumped over. */
void mar_clock_follow(mar_clock *c, double position, double rate, double period, double catch_up);

#endif
