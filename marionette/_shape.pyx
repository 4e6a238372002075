# cython: language_level=3, boundscheck=False, wraparound=False
"""Binding of the offline pragmatic filter (ext/mar_shape.c).

Validates arguments, then calls C (inside ``with nogil`` where the call may
take time). Returns C status codes and numpy arrays; marionette.shape raises.
Units: positions [unit], times [s], ticks [tick], speeds [unit/s],
accelerations [unit/s^2].
"""
import numpy as np
cimport numpy as cnp
from libc.stdint cimport int32_t, int64_t
from libc.stdlib cimport calloc, free

from marionette.errors import ArgumentError

cnp.import_array()


cdef extern from "mar_shape.h" nogil:
    enum:
        MAR_SHAPE_INFEASIBLE
        MAR_SHAPE_REDUCE
        MAR_SHAPE_BORROW
        MAR_SHAPE_REJECT
        MAR_SHAPE_ACT_REDUCED
        MAR_SHAPE_ACT_BORROWED
        MAR_SHAPE_ACT_REJECTED
        MAR_SHAPE_OPEN_START
        MAR_SHAPE_OPEN_END
    ctypedef struct mar_shape_profile:
        double t0
        double duration
        double x0
        double x1
        double accel
        double peak_speed
        double ramp
        double smooth
        double accel_end
        double ramp_end
        double turn
        double turn_end
        int32_t open
        int32_t reserved
    ctypedef struct mar_shape_extremum:
        int64_t tick
        int64_t rest_end
        double value
        int32_t kind
        int32_t reserved
    ctypedef struct mar_shape_segment:
        int64_t from_tick
        int64_t depart_tick
        int64_t arrive_tick
        double target
        double shortfall
        double reduced_by
        int32_t action
        int32_t reserved
        mar_shape_profile profile
    ctypedef struct mar_shape_options:
        double period
        double max_speed
        double max_accel
        double pos_min
        double pos_max
        double prominence
        double rest_tolerance
        int policy
        double lag
        double pos_margin
        int64_t first_depart
    double mar_shape_reach(double duration, double max_speed, double max_accel)
    double mar_shape_min_time(double distance, double max_speed, double max_accel)
    double mar_shape_reach_lag(double duration, double max_speed, double max_accel, double lag,
                               double *smooth)
    void mar_shape_lag_limits(double smooth, double lag, double max_speed, double max_accel,
                              double *speed, double *accel)
    int mar_shape_plan_lag(double x0, double x1, double t0, double duration,
                           double max_speed, double max_accel, double lag, mar_shape_profile *p)
    int mar_shape_plan(double x0, double x1, double t0, double duration,
                       double max_speed, double max_accel, mar_shape_profile *p)
    void mar_shape_eval(const mar_shape_profile *p, double t, double *x, double *v, double *a)
    int mar_shape_extrema(const double *x, size_t n, double prominence, double rest_tolerance,
                          mar_shape_extremum *out, size_t cap, size_t *count)
    int mar_shape_axis(const mar_shape_options *opt, const double *x, size_t n,
                       mar_shape_extremum *ext, size_t ext_cap, size_t *n_ext,
                       mar_shape_segment *seg, size_t seg_cap, size_t *n_seg, double *out)


INFEASIBLE = MAR_SHAPE_INFEASIBLE
POLICIES = {"reduce": MAR_SHAPE_REDUCE, "borrow": MAR_SHAPE_BORROW, "reject": MAR_SHAPE_REJECT}
ACT_REDUCED = MAR_SHAPE_ACT_REDUCED
ACT_BORROWED = MAR_SHAPE_ACT_BORROWED
ACT_REJECTED = MAR_SHAPE_ACT_REJECTED

# A move, as mar_shape_profile.
PROFILE_FIELDS = ("t0", "duration", "x0", "x1", "accel", "peak_speed", "ramp", "smooth",
                  "accel_end", "ramp_end", "turn", "turn_end", "open")
EXTREMUM_DTYPE = np.dtype([
    ("tick", "i8"), ("rest_end", "i8"),     # climax and last tick of its rest [tick]
    ("value", "f8"),                        # taught position [unit]
    ("kind", "i4"),                         # +1 max, -1 min, 0 first/last sample
])
SEGMENT_DTYPE = np.dtype([
    ("from_tick", "i8"), ("depart_tick", "i8"), ("arrive_tick", "i8"),   # [tick]
    ("target", "f8"),                       # taught end position [unit]
    ("shortfall", "f8"),                    # |D| - reachable |D| (nominal window) [unit]
    ("reduced_by", "f8"),                   # how far the end was moved [unit]
    ("action", "i4"),                       # ACT_* bits
    ("t0", "f8"), ("duration", "f8"),       # [s]
    ("x0", "f8"), ("x1", "f8"),             # [unit]
    ("accel", "f8"), ("peak_speed", "f8"),  # [unit/s^2], [unit/s]
    ("ramp", "f8"),                         # [s]
    ("smooth", "f8"),                       # moving-average window [s]
    ("accel_end", "f8"), ("ramp_end", "f8"),  # the core's last ramp [unit/s^2], [s]
    ("turn", "f8"), ("turn_end", "f8"),     # acceleration at an open start, end [unit/s^2]
    ("open", "i4"),                         # OPEN_* bits: ends that turn without rest
])
OPEN_START = MAR_SHAPE_OPEN_START
OPEN_END = MAR_SHAPE_OPEN_END


def reach(double duration, double max_speed, double max_accel):
    """Largest distance [unit] a rest-to-rest move of duration [s] can cover."""
    return mar_shape_reach(duration, max_speed, max_accel)


def min_time(double distance, double max_speed, double max_accel):
    """Shortest duration [s] of a rest-to-rest move over |distance| [unit]."""
    return mar_shape_min_time(distance, max_speed, max_accel)


def reach_lag(double duration, double max_speed, double max_accel, double lag):
    """(reach [unit], smoothing window [s]) of a rest-to-rest move whose
    command x + lag*x' [lag: s] keeps the limits."""
    cdef double w = 0.0
    cdef double r = mar_shape_reach_lag(duration, max_speed, max_accel, lag, &w)
    return r, w


def lag_limits(double smooth, double lag, double max_speed, double max_accel):
    """(speed [unit/s], accel [unit/s^2]) a core is planned to for a window smooth [s]."""
    cdef double v = 0.0, a = 0.0
    mar_shape_lag_limits(smooth, lag, max_speed, max_accel, &v, &a)
    return v, a


def plan(double x0, double x1, double t0, double duration, double max_speed, double max_accel,
         double lag=0.0):
    """(status, profile dict or None): 0 fits, INFEASIBLE, or a negative errno.
    lag [s] > 0: planned for the command x + lag*x' (mar_shape_plan_lag)."""
    cdef mar_shape_profile p
    cdef int r = mar_shape_plan_lag(x0, x1, t0, duration, max_speed, max_accel, lag, &p)
    if r != 0:
        return r, None
    return r, _profile_dict(&p)


cdef dict _profile_dict(const mar_shape_profile *p):
    return {"t0": p.t0, "duration": p.duration, "x0": p.x0, "x1": p.x1,
            "accel": p.accel, "peak_speed": p.peak_speed, "ramp": p.ramp, "smooth": p.smooth,
            "accel_end": p.accel_end, "ramp_end": p.ramp_end, "turn": p.turn,
            "turn_end": p.turn_end, "open": p.open}



cdef int _profile_from(prof, mar_shape_profile *p) except -1:
    p.t0 = prof["t0"]
    p.duration = prof["duration"]
    p.x0 = prof["x0"]
    p.x1 = prof["x1"]
    p.accel = prof["accel"]
    p.peak_speed = prof["peak_speed"]
    p.ramp = prof["ramp"]
    p.smooth = prof["smooth"]
    p.accel_end = prof["accel_end"]
    p.ramp_end = prof["ramp_end"]
    p.turn = prof["turn"]
    p.turn_end = prof["turn_end"]
    p.open = prof["open"]
    p.reserved = 0
    return 0


def evaluate(prof, t):
    """(x, v, a) of a move (dict or segment record) at times t [s]: [unit],
    [unit/s], [unit/s^2]."""
    cdef mar_shape_profile p
    _profile_from(prof, &p)
    cdef cnp.ndarray[cnp.float64_t, ndim=1, mode="c"] tt = np.ascontiguousarray(
        np.atleast_1d(t), dtype=np.float64).ravel()
    cdef Py_ssize_t n = tt.shape[0], i
    cdef cnp.ndarray[cnp.float64_t, ndim=1] x = np.empty(n)
    cdef cnp.ndarray[cnp.float64_t, ndim=1] v = np.empty(n)
    cdef cnp.ndarray[cnp.float64_t, ndim=1] a = np.empty(n)
    cdef double xi, vi, ai
    for i in range(n):
        mar_shape_eval(&p, tt[i], &xi, &vi, &ai)
        x[i] = xi
        v[i] = vi
        a[i] = ai
    return x, v, a


def extrema(x, double prominence, double rest_tolerance):
    """(status, EXTREMUM_DTYPE array) of the points of rest of x [unit]."""
    cdef cnp.ndarray[cnp.float64_t, ndim=1, mode="c"] xx = np.ascontiguousarray(x, dtype=np.float64)
    cdef size_t n = xx.shape[0], count = 0, i
    if n == 0:
        raise ArgumentError("extrema: empty trajectory")
    cdef mar_shape_extremum *buf = <mar_shape_extremum *>calloc(n, sizeof(mar_shape_extremum))
    if buf == NULL:
        raise MemoryError()
    cdef int r
    try:
        with nogil:
            r = mar_shape_extrema(&xx[0], n, prominence, rest_tolerance, buf, n, &count)
        out = np.zeros(count if r == 0 else 0, dtype=EXTREMUM_DTYPE)
        if r == 0:
            for i in range(count):
                out[i] = (buf[i].tick, buf[i].rest_end, buf[i].value, buf[i].kind)
        return r, out
    finally:
        free(buf)


def shape_axis(x, double period, double max_speed, double max_accel, double pos_min,
               double pos_max, double prominence, double rest_tolerance, str policy,
               double lag=0.0, double pos_margin=0.0, int64_t first_depart=0):
    """Shape one axis's trajectory x [unit] (one sample per tick of period [s]);
    lag [s], pos_margin [unit], first_depart [tick]: mar_shape_options.

    Returns (status, shaped [unit], EXTREMUM_DTYPE array, SEGMENT_DTYPE array);
    status is the number of infeasible segments (>= 0) or a negative errno.
    """
    if policy not in POLICIES:
        raise ArgumentError(f"policy must be one of {sorted(POLICIES)}, not {policy!r}")
    cdef cnp.ndarray[cnp.float64_t, ndim=1, mode="c"] xx = np.ascontiguousarray(x, dtype=np.float64)
    cdef size_t n = xx.shape[0], n_ext = 0, n_seg = 0, i
    if n == 0:
        raise ArgumentError("shape_axis: empty trajectory")
    cdef mar_shape_options opt
    opt.period = period
    opt.max_speed = max_speed
    opt.max_accel = max_accel
    opt.pos_min = pos_min
    opt.pos_max = pos_max
    opt.prominence = prominence
    opt.rest_tolerance = rest_tolerance
    opt.policy = POLICIES[policy]
    opt.lag = lag
    opt.pos_margin = pos_margin
    opt.first_depart = first_depart
    cdef cnp.ndarray[cnp.float64_t, ndim=1, mode="c"] out = np.empty(n)
    cdef mar_shape_extremum *ext = <mar_shape_extremum *>calloc(n, sizeof(mar_shape_extremum))
    cdef mar_shape_segment *seg = <mar_shape_segment *>calloc(n, sizeof(mar_shape_segment))
    cdef int r
    cdef mar_shape_segment *s
    try:
        if ext == NULL or seg == NULL:
            raise MemoryError()
        with nogil:
            r = mar_shape_axis(&opt, &xx[0], n, ext, n, &n_ext, seg, n, &n_seg, &out[0])
        if r < 0:
            return r, None, None, None
        extr = np.zeros(n_ext, dtype=EXTREMUM_DTYPE)
        for i in range(n_ext):
            extr[i] = (ext[i].tick, ext[i].rest_end, ext[i].value, ext[i].kind)
        segs = np.zeros(n_seg, dtype=SEGMENT_DTYPE)
        for i in range(n_seg):
            s = &seg[i]
            segs[i] = (s.from_tick, s.depart_tick, s.arrive_tick, s.target, s.shortfall,
                       s.reduced_by, s.action, s.profile.t0, s.profile.duration,
                       s.profile.x0, s.profile.x1, s.profile.accel, s.profile.peak_speed,
                       s.profile.ramp, s.profile.smooth, s.profile.accel_end,
                       s.profile.ramp_end, s.profile.turn, s.profile.turn_end, s.profile.open)
        return r, out, extr, segs
    finally:
        free(ext)
        free(seg)
