# cython: language_level=3, boundscheck=False, wraparound=False
"""Binding of the music follower (ext/mar_follow.c).

Validates arguments, then calls C; a whole array of live frames runs
through the C step inside ``with nogil``. Returns C status codes and numpy
arrays; marionette.music.follower raises. Units: positions [stored ticks], rates
[stored ticks per tick], loudness linear [full scale], times [ns].
"""
import numpy as np
cimport numpy as cnp
from libc.stdint cimport int64_t, uint32_t, uint64_t
from libc.math cimport NAN
from posix.time cimport clock_gettime, timespec, CLOCK_MONOTONIC

from marionette.errors import ArgumentError

cnp.import_array()


cdef extern from "mar_follow.h" nogil:
    enum:
        MAR_FOLLOW_SMOOTH
        MAR_FOLLOW_PAPER
        MAR_FOLLOW_MODEL
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
        double tick_period
    ctypedef struct mar_follow_option_info:
        const char *name
        int kind
        size_t offset
        double default_value
        double lo
        double hi
        const char *unit
        const char *why
    const mar_follow_option_info mar_follow_option_table[]
    const size_t mar_follow_option_count
    enum:
        MAR_FOLLOW_KIND_int
        MAR_FOLLOW_KIND_double
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
    enum:
        MAR_FOLLOW_MAX_BANDS
    ctypedef struct mar_follow_frame:
        double loudness
        double onset
        size_t n_bands
        double bands[MAR_FOLLOW_MAX_BANDS]
    ctypedef struct mar_follow_music:
        const double *loudness
        const double *onset
        const double *bands
        size_t n_bands
        size_t n
    mar_follow *mar_follow_create_music(const mar_follow_options *opt, const mar_follow_music *music,
                                        int *status)
    size_t mar_follow_tick(mar_follow *f, const mar_follow_frame *frames, size_t n, int64_t elapsed,
                           mar_follow_out *out)
    void mar_follow_default_options(mar_follow_options *opt)
    int mar_follow_check_options(const mar_follow_options *opt, const char **problem)
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


MAX_BANDS = MAR_FOLLOW_MAX_BANDS     # band levels per frame, at most
MODES = {"smooth": MAR_FOLLOW_SMOOTH, "paper": MAR_FOLLOW_PAPER, "model": MAR_FOLLOW_MODEL}
STATES = ("searching", "locked", "holding", "paused", "waiting")    # index = state code
SEARCHING, LOCKED, HOLDING, PAUSED, WAITING = (MAR_FOLLOW_SEARCHING, MAR_FOLLOW_LOCKED,
                                               MAR_FOLLOW_HOLDING, MAR_FOLLOW_PAUSED,
                                               MAR_FOLLOW_WAITING)
FLAGS = {"no_frame": MAR_FOLLOW_F_NO_FRAME, "bad_input": MAR_FOLLOW_F_BAD_INPUT,
         "measured": MAR_FOLLOW_F_MEASURED, "quiet": MAR_FOLLOW_F_QUIET, "jump": MAR_FOLLOW_F_JUMP,
         "search": MAR_FOLLOW_F_SEARCH, "rate_limit": MAR_FOLLOW_F_RATE_LIMIT, "end": MAR_FOLLOW_F_END}


def _option_table():
    """The C table (MAR_FOLLOW_OPTIONS in ext/mar_follow.h): name -> dict of
    kind ("int" or "double"), default, lo, hi (allowed, inclusive), unit
    ("s": a time, turned into ticks at create) and why (one line)."""
    table = {}
    cdef size_t i
    for i in range(mar_follow_option_count):
        info = &mar_follow_option_table[i]
        table[info.name.decode()] = {
            "kind": "int" if info.kind == MAR_FOLLOW_KIND_int else "double",
            "default": info.default_value, "lo": info.lo, "hi": info.hi,
            "unit": info.unit.decode(), "why": info.why.decode(), "offset": info.offset}
    return table


OPTIONS = _option_table()


cdef dict _options_dict(mar_follow_options *o):
    """Every option by name, in its table unit; mode by name; tick_period [s]."""
    cdef char *base = <char *>o
    out = {"tick_period": o.tick_period}
    for name, info in OPTIONS.items():
        if info["kind"] == "int":
            out[name] = (<int *>(base + <size_t>info["offset"]))[0]
        else:
            out[name] = (<double *>(base + <size_t>info["offset"]))[0]
    out["mode"] = {v: k for k, v in MODES.items()}.get(out["mode"], out["mode"])
    return out


def default_options():
    """The C defaults (mar_follow_default_options), as a dict in the
    table's units (times in s)."""
    cdef mar_follow_options o
    mar_follow_default_options(&o)
    return _options_dict(&o)


cdef int _set_options(mar_follow_options *o, dict options) except -1:
    """Options by name into o; KeyError for an unknown name, ValueError for
    a value of the wrong kind (C checks the ranges)."""
    cdef char *base = <char *>o
    for key, value in options.items():
        if key == "tick_period":
            o.tick_period = float(value)
            continue
        info = OPTIONS.get(key)
        if info is None:
            raise KeyError(key)
        if key == "mode":
            if value not in MODES:
                raise ArgumentError(key)
            value = MODES[value]
        if info["kind"] == "int":
            if isinstance(value, bool) or int(value) != value or not (-2**31 <= value < 2**31):
                raise ArgumentError(key)
            (<int *>(base + <size_t>info["offset"]))[0] = int(value)
        else:
            (<double *>(base + <size_t>info["offset"]))[0] = float(value)
    return 0


cdef class Follower:
    """The C follower over a stored loudness array (linear, one value per tick).

    ``Follower(stored, options, onset=None, bands=None)``: options is a dict
    of mar_follow_options fields (see default_options); onset the stored
    onset strength [dB] or None; bands the stored band levels (ticks,
    n_bands) [full scale] or None (mar_follow_create_music); raises KeyError
    for an unknown name and ValueError(status) when C refuses the options or
    the stored values.
    """

    cdef mar_follow *f
    cdef readonly dict options
    cdef readonly size_t n_bands

    def __cinit__(self, stored, dict options=None, onset=None, bands=None):
        cdef mar_follow_options o
        cdef int status = 0
        mar_follow_default_options(&o)
        _set_options(&o, options or {})
        self.options = _options_dict(&o)
        cdef cnp.ndarray[cnp.float64_t, ndim=1, mode="c"] s = np.ascontiguousarray(stored, dtype=np.float64)
        cdef size_t n = s.shape[0]
        if n == 0:
            raise ArgumentError(-22)
        cdef mar_follow_music music
        music.loudness = &s[0]
        music.onset = NULL
        music.bands = NULL
        music.n_bands = 0
        music.n = n
        cdef cnp.ndarray[cnp.float64_t, ndim=1, mode="c"] on
        cdef cnp.ndarray[cnp.float64_t, ndim=2, mode="c"] bd
        if onset is not None:
            on = np.ascontiguousarray(onset, dtype=np.float64)
            if on.shape[0] != n:
                raise ArgumentError(-22)
            music.onset = &on[0]
        if bands is not None:
            bd = np.ascontiguousarray(bands, dtype=np.float64)
            if bd.ndim != 2 or bd.shape[0] != n or bd.shape[1] == 0:
                raise ArgumentError(-22)
            music.bands = &bd[0, 0]
            music.n_bands = bd.shape[1]
        with nogil:
            self.f = mar_follow_create_music(&o, &music, &status)
        self.n_bands = music.n_bands
        if self.f == NULL:
            raise ArgumentError(status)

    def __dealloc__(self):
        if self.f != NULL:
            mar_follow_destroy(self.f)
            self.f = NULL

    def step(self, double live, double onset=NAN, bands=None):
        """One tick of the show's clock (mar_follow_tick) with one live frame,
        or none when live is NaN, and its band levels (n_bands,) [full scale]
        or None: (position [stored ticks], rate [stored ticks per tick],
        confidence [0..1], state code, flags)."""
        cdef mar_follow_out out
        cdef mar_follow_frame frame
        frame.loudness = live
        frame.onset = onset
        frame.n_bands = 0
        if bands is not None:
            if len(bands) > MAR_FOLLOW_MAX_BANDS:
                raise ArgumentError(-22)
            frame.n_bands = len(bands)
            for i, v in enumerate(bands):
                frame.bands[i] = v
        mar_follow_tick(self.f, &frame, 0 if live != live else 1, 1, &out)
        return out.position, out.rate, out.confidence, out.state, out.flags

    def run(self, live, onset=None, bands=None, bint timing=False):
        """One tick per entry of ``live`` (NaN: no frame that tick) through
        mar_follow_tick, as the engine drives it, without the GIL; onset
        (n,) [dB] and bands (n, n_bands) [full scale] the frames' own, or
        None. Returns a dict of arrays: position, rate, confidence, state
        (int8), flags (uint32), and with timing also ns (int64: wall time of
        each step [ns], CLOCK_MONOTONIC around it)."""
        cdef cnp.ndarray[cnp.float64_t, ndim=1, mode="c"] x = np.ascontiguousarray(live, dtype=np.float64)
        cdef Py_ssize_t n = x.shape[0], i
        cdef size_t b, nb = 0
        cdef cnp.ndarray[cnp.float64_t, ndim=1, mode="c"] ov = (
            np.full(n, np.nan) if onset is None else np.ascontiguousarray(onset, dtype=np.float64))
        if ov.shape[0] != n:
            raise ArgumentError(-22)
        cdef cnp.ndarray[cnp.float64_t, ndim=2, mode="c"] bv = np.zeros((n, 1))
        if bands is not None:
            bv = np.ascontiguousarray(bands, dtype=np.float64)
            if bv.ndim != 2 or bv.shape[0] != n or bv.shape[1] > MAR_FOLLOW_MAX_BANDS:
                raise ArgumentError(-22)
            nb = bv.shape[1]
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
                frame.n_bands = nb
                for b in range(nb):
                    frame.bands[b] = bv[i, b]
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


def options_problem(dict options=None):
    """What the C follower refuses in options (mar_follow_check_options),
    in words; None when it takes them. Raises KeyError, ValueError as the
    Follower does for an unknown name or a value of the wrong kind."""
    cdef mar_follow_options o
    cdef const char *problem = NULL
    mar_follow_default_options(&o)
    _set_options(&o, options or {})
    if mar_follow_check_options(&o, &problem) == 0:
        return None
    return problem.decode()


def options_bytes(dict options=None):
    """A mar_follow_options filled from the C defaults and options, as bytes:
    how marionette._core.CoreEngine takes the follower it runs in the tick."""
    cdef mar_follow_options o
    mar_follow_default_options(&o)
    _set_options(&o, options or {})
    return (<char *>&o)[:sizeof(mar_follow_options)]
