# cython: language_level=3, boundscheck=False, wraparound=False
"""Binding of the music follower (ext/mar_follow.c).

Validates arguments, then calls C; a whole array of live frames runs
through the C step inside ``with nogil``. Returns C status codes and numpy
arrays; marionette.follow raises. Units: positions [stored ticks], rates
[stored ticks per tick], loudness linear [full scale], times [ns].
"""
import numpy as np
cimport numpy as cnp
from libc.stdint cimport int64_t, uint32_t, uint64_t
from libc.math cimport NAN
from posix.time cimport clock_gettime, timespec, CLOCK_MONOTONIC

cnp.import_array()


cdef extern from "mar_follow.h" nogil:
    enum:
        MAR_FOLLOW_SMOOTH
        MAR_FOLLOW_PAPER
        MAR_FOLLOW_SEARCHING
        MAR_FOLLOW_LOCKED
        MAR_FOLLOW_HOLDING
        MAR_FOLLOW_PAUSED
        MAR_FOLLOW_WAITING
        MAR_FOLLOW_F_NO_FRAME
        MAR_FOLLOW_F_BAD_INPUT
        MAR_FOLLOW_F_MEASURED
        MAR_FOLLOW_F_QUIET
        MAR_FOLLOW_F_JUMP
        MAR_FOLLOW_F_SEARCH
        MAR_FOLLOW_F_RATE_LIMIT
        MAR_FOLLOW_F_END
    ctypedef struct mar_follow_options:
        int mode
        double rate_min
        double rate_max
        double delay
        double range_db
        size_t window
        size_t min_window
        size_t verify_window
        size_t lock_window
        size_t paper_window
        size_t coarse
        size_t search_window
        double rate_step
        size_t search_budget
        double track_threshold
        double lock_threshold
        double lock_margin
        double hold_after
        double search_after
        double lost_after
        double quiet_lost_after
        double pause_after
        double quiet_db
        double meas_noise
        double rate_noise
        double onset_weight
    ctypedef struct mar_follow_out:
        double position
        double rate
        double confidence
        int state
        uint32_t flags
    ctypedef struct mar_follow_counters:
        uint64_t steps
        uint64_t frames
        uint64_t missing
        uint64_t bad_input
        uint64_t measurements
        uint64_t rejected
        uint64_t locks
        uint64_t pauses
        uint64_t resumes
        uint64_t search_steps
    ctypedef struct mar_follow:
        pass
    ctypedef struct mar_follow_frame:
        double loudness
        double onset
    size_t mar_follow_tick(mar_follow *f, const mar_follow_frame *frames, size_t n, int64_t elapsed,
                           mar_follow_out *out)
    void mar_follow_default_options(mar_follow_options *opt)
    mar_follow *mar_follow_create(const mar_follow_options *opt, const double *stored, size_t n_stored,
                                  int *status)
    mar_follow *mar_follow_create_onsets(const mar_follow_options *opt, const double *stored,
                                         const double *onset, size_t n_stored, int *status)
    void mar_follow_step_onset(mar_follow *f, double live, double onset, mar_follow_out *out)
    void mar_follow_destroy(mar_follow *f)
    void mar_follow_step(mar_follow *f, double live, mar_follow_out *out)
    void mar_follow_reset(mar_follow *f, double position)
    void mar_follow_cue(mar_follow *f, double position)
    void mar_follow_get_counters(const mar_follow *f, mar_follow_counters *c)
    size_t mar_follow_stored_length(const mar_follow *f)


MODES = {"smooth": MAR_FOLLOW_SMOOTH, "paper": MAR_FOLLOW_PAPER}
STATES = ("searching", "locked", "holding", "paused", "waiting")    # index = state code
SEARCHING, LOCKED, HOLDING, PAUSED, WAITING = (MAR_FOLLOW_SEARCHING, MAR_FOLLOW_LOCKED,
                                               MAR_FOLLOW_HOLDING, MAR_FOLLOW_PAUSED,
                                               MAR_FOLLOW_WAITING)
FLAGS = {"no_frame": MAR_FOLLOW_F_NO_FRAME, "bad_input": MAR_FOLLOW_F_BAD_INPUT,
         "measured": MAR_FOLLOW_F_MEASURED, "quiet": MAR_FOLLOW_F_QUIET, "jump": MAR_FOLLOW_F_JUMP,
         "search": MAR_FOLLOW_F_SEARCH, "rate_limit": MAR_FOLLOW_F_RATE_LIMIT, "end": MAR_FOLLOW_F_END}
# option name -> kind: "i" size_t [1 or ticks], "f" double; "mode" is a MODES name
OPTION_KINDS = {"mode": "mode", "rate_min": "f", "rate_max": "f", "delay": "f", "range_db": "f",
                "window": "i", "min_window": "i", "verify_window": "i", "lock_window": "i", "paper_window": "i",
                "coarse": "i", "search_window": "i", "rate_step": "f", "search_budget": "i",
                "track_threshold": "f", "lock_threshold": "f", "lock_margin": "f",
                "hold_after": "f", "search_after": "f", "lost_after": "f", "quiet_lost_after": "f",
                "pause_after": "f", "quiet_db": "f", "meas_noise": "f", "rate_noise": "f",
                "onset_weight": "f"}


cdef dict _options_dict(mar_follow_options *o):
    mode = [k for k, v in MODES.items() if v == o.mode][0]
    return {"mode": mode, "rate_min": o.rate_min, "rate_max": o.rate_max, "delay": o.delay,
            "range_db": o.range_db, "window": o.window, "min_window": o.min_window,
            "verify_window": o.verify_window, "lock_window": o.lock_window, "paper_window": o.paper_window, "coarse": o.coarse,
            "search_window": o.search_window, "rate_step": o.rate_step,
            "search_budget": o.search_budget, "track_threshold": o.track_threshold,
            "lock_threshold": o.lock_threshold, "lock_margin": o.lock_margin,
            "hold_after": o.hold_after, "search_after": o.search_after, "lost_after": o.lost_after,
            "quiet_lost_after": o.quiet_lost_after, "pause_after": o.pause_after,
            "quiet_db": o.quiet_db, "meas_noise": o.meas_noise, "rate_noise": o.rate_noise,
            "onset_weight": o.onset_weight}


def default_options():
    """The C defaults (mar_follow_default_options), as a dict; window
    lengths and times in ticks."""
    cdef mar_follow_options o
    mar_follow_default_options(&o)
    return _options_dict(&o)


cdef int _set_options(mar_follow_options *o, dict options) except -1:
    for key, value in options.items():
        kind = OPTION_KINDS.get(key)
        if kind is None:
            raise KeyError(key)
        if kind == "mode":
            o.mode = MODES[value]
        elif kind == "i":
            if isinstance(value, bool) or int(value) != value or value < 0:
                raise ValueError(key)
            v = int(value)
            if key == "window": o.window = v
            elif key == "min_window": o.min_window = v
            elif key == "verify_window": o.verify_window = v
            elif key == "lock_window": o.lock_window = v
            elif key == "paper_window": o.paper_window = v
            elif key == "coarse": o.coarse = v
            elif key == "search_window": o.search_window = v
            elif key == "search_budget": o.search_budget = v
        else:
            x = float(value)
            if key == "rate_min": o.rate_min = x
            elif key == "rate_max": o.rate_max = x
            elif key == "delay": o.delay = x
            elif key == "range_db": o.range_db = x
            elif key == "rate_step": o.rate_step = x
            elif key == "track_threshold": o.track_threshold = x
            elif key == "lock_threshold": o.lock_threshold = x
            elif key == "lock_margin": o.lock_margin = x
            elif key == "hold_after": o.hold_after = x
            elif key == "search_after": o.search_after = x
            elif key == "lost_after": o.lost_after = x
            elif key == "quiet_lost_after": o.quiet_lost_after = x
            elif key == "pause_after": o.pause_after = x
            elif key == "quiet_db": o.quiet_db = x
            elif key == "meas_noise": o.meas_noise = x
            elif key == "rate_noise": o.rate_noise = x
            elif key == "onset_weight": o.onset_weight = x
    return 0


cdef class Follower:
    """The C follower over a stored loudness array (linear, one value per tick).

    ``Follower(stored, options, onset=None)``: options is a dict of
    mar_follow_options fields (see default_options); onset the stored onset
    strength [dB] (mar_follow_create_onsets) or None; raises KeyError for an
    unknown name and ValueError(status) when C refuses the options or the
    stored values.
    """

    cdef mar_follow *f
    cdef readonly dict options

    def __cinit__(self, stored, dict options=None, onset=None):
        cdef mar_follow_options o
        cdef int status = 0
        mar_follow_default_options(&o)
        _set_options(&o, options or {})
        self.options = _options_dict(&o)
        cdef cnp.ndarray[cnp.float64_t, ndim=1, mode="c"] s = np.ascontiguousarray(stored, dtype=np.float64)
        cdef size_t n = s.shape[0]
        if n == 0:
            raise ValueError(-22)
        cdef cnp.ndarray[cnp.float64_t, ndim=1, mode="c"] on
        if onset is not None:
            on = np.ascontiguousarray(onset, dtype=np.float64)
            if on.shape[0] != n:
                raise ValueError(-22)
            with nogil:
                self.f = mar_follow_create_onsets(&o, &s[0], &on[0], n, &status)
        else:
            with nogil:
                self.f = mar_follow_create(&o, &s[0], n, &status)
        if self.f == NULL:
            raise ValueError(status)

    def __dealloc__(self):
        if self.f != NULL:
            mar_follow_destroy(self.f)
            self.f = NULL

    def step(self, double live, double onset=NAN):
        """One tick of the show's clock (mar_follow_tick) with one live frame,
        or none when live is NaN: (position [stored ticks], rate [stored ticks
        per tick], confidence [0..1], state code, flags)."""
        cdef mar_follow_out out
        cdef mar_follow_frame frame
        frame.loudness = live
        frame.onset = onset
        mar_follow_tick(self.f, &frame, 0 if live != live else 1, 1, &out)
        return out.position, out.rate, out.confidence, out.state, out.flags

    def run(self, live, onset=None, bint timing=False):
        """One tick per entry of ``live`` (NaN: no frame that tick) through
        mar_follow_tick, as the engine drives it, without the GIL. Returns a dict of arrays: position, rate,
        confidence, state (int8), flags (uint32), and with timing also ns
        (int64: wall time of each step [ns], CLOCK_MONOTONIC around it)."""
        cdef cnp.ndarray[cnp.float64_t, ndim=1, mode="c"] x = np.ascontiguousarray(live, dtype=np.float64)
        cdef Py_ssize_t n = x.shape[0], i
        cdef cnp.ndarray[cnp.float64_t, ndim=1, mode="c"] ov = (
            np.full(n, np.nan) if onset is None else np.ascontiguousarray(onset, dtype=np.float64))
        if ov.shape[0] != n:
            raise ValueError(-22)
        position = np.empty(n)
        rate = np.empty(n)
        confidence = np.empty(n)
        state = np.empty(n, dtype=np.int8)
        flags = np.empty(n, dtype=np.uint32)
        ns = np.zeros(n, dtype=np.int64)
        cdef double[::1] pv = position, rv = rate, cv = confidence
        cdef cnp.int8_t[::1] sv = state
        cdef uint32_t[::1] fv = flags
        cdef int64_t[::1] tv = ns
        cdef mar_follow_out out
        cdef mar_follow_frame frame
        cdef timespec t0, t1
        with nogil:
            for i in range(n):
                if timing:
                    clock_gettime(CLOCK_MONOTONIC, &t0)
                frame.loudness = x[i]
                frame.onset = ov[i]
                mar_follow_tick(self.f, &frame, 0 if x[i] != x[i] else 1, 1, &out)
                if timing:
                    clock_gettime(CLOCK_MONOTONIC, &t1)
                    tv[i] = (t1.tv_sec - t0.tv_sec) * 1000000000 + (t1.tv_nsec - t0.tv_nsec)
                pv[i] = out.position
                rv[i] = out.rate
                cv[i] = out.confidence
                sv[i] = <cnp.int8_t>out.state
                fv[i] = out.flags
        result = {"position": position, "rate": rate, "confidence": confidence, "state": state,
                  "flags": flags}
        if timing:
            result["ns"] = ns
        return result

    def reset(self, double position=NAN):
        """Known position [stored ticks] of the live music now; NaN: unknown."""
        mar_follow_reset(self.f, position)

    def cue(self, double position=NAN):
        """The music will start at position [stored ticks]; NaN: unknown."""
        mar_follow_cue(self.f, position)

    def counters(self):
        cdef mar_follow_counters c
        mar_follow_get_counters(self.f, &c)
        return {"steps": c.steps, "frames": c.frames, "missing": c.missing, "bad_input": c.bad_input,
                "measurements": c.measurements, "rejected": c.rejected, "locks": c.locks,
                "pauses": c.pauses, "resumes": c.resumes, "search_steps": c.search_steps}

    @property
    def stored_length(self):
        """Stored frames [ticks]."""
        return mar_follow_stored_length(self.f)


def options_bytes(dict options=None):
    """A mar_follow_options filled from the C defaults and options, as bytes:
    how marionette._core.CoreEngine takes the follower it runs in the tick."""
    cdef mar_follow_options o
    mar_follow_default_options(&o)
    _set_options(&o, options or {})
    return (<char *>&o)[:sizeof(mar_follow_options)]
