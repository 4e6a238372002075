# cython: language_level=3, boundscheck=False, wraparound=False
"""Binding of the C tick engine (ext/); its setpoints are encoded by the
protocol codec of firmware_protocol/ (bound on its own in _protocol.pyx).

Validates arguments, then calls C, inside ``with nogil`` where the call may
take time. Returns the C status codes; marionette.engine raises.
"""
import numpy as np
cimport numpy as cnp
from libc.stdint cimport int32_t, int64_t, uint8_t, uint32_t, uint64_t
from libc.stdlib cimport calloc, free
from libc.math cimport NAN
from libc.string cimport memcpy

from marionette._cengine cimport *
from marionette.errors import ArgumentError, EngineError

cnp.import_array()

LEAD_NONE = 0           # enum mar_lead_mode
LEAD_MEAN_DELAY = 1
LEAD_DEAD_TIME_LAG = 2
INTERP_LINEAR = 0       # enum mar_interp
INTERP_CUBIC = 1
SINK_NONE = MAR_SINK_NONE
SINK_FD = MAR_SINK_FD
SINK_RING = MAR_SINK_RING
PROTOCOL_SERIAL = MAR_SINK_SERIAL   # enum mar_sink_protocol
PROTOCOL_CAN = MAR_SINK_CAN
CAN_RECORD_BYTES = MAR_CAN_RECORD_BYTES
# the flight record's flags, from ext/mar_engine.h (MAR_FLAG_*)
FLAG_LIMITED = MAR_FLAG_LIMITED         # some axis could not follow its target this tick
FLAG_END = MAR_FLAG_END                 # the playback position reached the end of the show
FLAG_BAD_INPUT = MAR_FLAG_BAD_INPUT     # a non-finite rate, seek or loudness was refused
FLAG_MOVING = MAR_FLAG_MOVING           # online moves drive the commands
FLAG_HOLDING = MAR_FLAG_HOLDING         # the figure holds a pose
FLAG_UNFOLLOWED = MAR_FLAG_UNFOLLOWED   # the music is not followed: the follower searches after it had a place
FLAG_SOURCE_LOST = MAR_FLAG_SOURCE_LOST   # the live source was lost (Engine.source_lost), latched
FLAG_NODE_SILENT = MAR_FLAG_NODE_SILENT   # a servo node is silent this tick
FLAG_FAULT_STOP = MAR_FLAG_FAULT_STOP     # a fault stopped the show (stop ramp, then hold), latched
FLAG_FAULT_HOLD = MAR_FLAG_FAULT_HOLD     # the show holds for a silent node until every node answers
FLAG_OVERRUNS = MAR_FLAG_OVERRUNS         # the overrun threshold was reached (with FAULT_STOP), latched
FLAG_LINK_LOST = MAR_FLAG_LINK_LOST       # the link is gone (EIO...): every node silent, latched
FLAG_STOPPING = MAR_FLAG_STOPPING         # a stop ramp drives the commands: its acceleration bound is on the drives
FAULT_CONTINUE = MAR_FAULT_CONTINUE       # enum mar_fault_reaction: [faults] silent_node
FAULT_STOP = MAR_FAULT_STOP
FAULT_HOLD = MAR_FAULT_HOLD
FAULT_ESTOP = MAR_FAULT_ESTOP
ON_LOST_FLYWHEEL = 0    # enum mar_on_lost
ON_LOST_HOLD = 1
REQUEST_GOTO = 1        # enum mar_request
REQUEST_BLEND = 2
REQUEST_STOP = 3

# Fields of one axis, in SI units, as the C mar_axis takes them.
AXIS_DTYPE = np.dtype([
    ("pos_min", "f8"), ("pos_max", "f8"),          # position limits [unit]
    ("max_speed", "f8"), ("max_accel", "f8"),      # [unit/s], [unit/s^2]
    ("dead_time", "f8"), ("time_constant", "f8"),  # [s]
    ("start", "f8"),                               # command before the first tick [unit]
    ("node", "u1"), ("channel", "u1"),
    ("scale", "f8"), ("offset", "f8"),             # counts = offset + scale * position
])


def record_dtype(size_t n_axes):
    """numpy dtype of one flight-recorder record (mirrors mar_record)."""
    return np.dtype([
        ("tick", "<i8"), ("time_ns", "<i8"),
        ("position", "<f8"), ("rate", "<f8"),
        ("live_loudness", "<f8"), ("stored_loudness", "<f8"),
        ("follow_confidence", "<f8"),
        ("flags", "<u4"), ("limited_axes", "<u4"),
        ("follow_state", "<i4"), ("node_alarms", "<u4"),
        ("command", "<f8", (n_axes,)),
        ("excess", "<f8", (n_axes,)),     # target - command where the limits acted, else 0 [unit]
    ])


cdef class CoreEngine:
    """Owns one mar_engine and its real-time loop."""
    cdef mar_engine *engine
    cdef mar_rtloop *loop
    cdef readonly size_t n_axes
    cdef readonly object record_dtype

    def __cinit__(self, double period, int lead_mode, int interp, axes,
                  cnp.ndarray[cnp.float64_t, ndim=2, mode="c"] show,
                  cnp.ndarray[cnp.float64_t, ndim=1, mode="c"] loudness,
                  size_t record_slots, size_t loudness_slots, bint start_holding=False,
                  bytes follow_options=None, onsets=None, double follow_cue=NAN,
                  int follow_on_lost=ON_LOST_FLYWHEEL, int on_silent_node=MAR_FAULT_CONTINUE,
                  uint64_t max_overruns=0, bands=None):
        """follow_options: a filled mar_follow_options (marionette._follow.options_bytes),
        or None to let the rate drive the playback clock; onsets: the stored
        onset strength (ticks,) [dB] for the follower, or None; follow_cue:
        where the live music starts [show ticks], NaN: unknown; follow_on_lost:
        ON_LOST_FLYWHEEL or ON_LOST_HOLD, what the show does while the music is
        not followed; on_silent_node: FAULT_*, the reaction to a silent node;
        max_overruns: real-time overruns that stop the show (0: none); bands:
        the stored band levels (ticks, n_bands) [full scale] for the
        follower, or None."""
        axes = np.ascontiguousarray(axes, dtype=AXIS_DTYPE)
        cdef size_t n_axes = axes.shape[0]
        if show.shape[0] != n_axes or loudness.shape[0] != show.shape[1]:
            raise ArgumentError("show must be (axes, ticks) and loudness (ticks,)")
        cdef cnp.ndarray[cnp.float64_t, ndim=1, mode="c"] c_onsets = None
        if onsets is not None:
            c_onsets = np.ascontiguousarray(onsets, dtype=np.float64)
            if c_onsets.shape[0] != show.shape[1]:
                raise ArgumentError("onsets must be (ticks,)")
        cdef cnp.ndarray[cnp.float64_t, ndim=2, mode="c"] c_bands = None
        if bands is not None:
            c_bands = np.ascontiguousarray(bands, dtype=np.float64)
            if c_bands.shape[0] != show.shape[1] or c_bands.shape[1] == 0:
                raise ArgumentError("bands must be (ticks, n_bands)")
        cdef mar_axis *c_axes = <mar_axis *>calloc(max(n_axes, 1), sizeof(mar_axis))
        if c_axes == NULL:
            raise MemoryError()
        cdef size_t j
        for j in range(n_axes):
            a = axes[j]
            c_axes[j].limits.pos_min = a["pos_min"]
            c_axes[j].limits.pos_max = a["pos_max"]
            c_axes[j].limits.max_speed = a["max_speed"]
            c_axes[j].limits.max_accel = a["max_accel"]
            c_axes[j].dead_time = a["dead_time"]
            c_axes[j].time_constant = a["time_constant"]
            c_axes[j].start = a["start"]
            c_axes[j].address.node = a["node"]
            c_axes[j].address.channel = a["channel"]
            c_axes[j].address.scale = a["scale"]
            c_axes[j].address.offset = a["offset"]
        cdef mar_engine_options opt
        opt.period = period
        opt.lead_mode = lead_mode
        opt.interp = interp
        opt.record_slots = record_slots
        opt.loudness_slots = loudness_slots
        opt.start_holding = start_holding
        opt.follow = follow_options is not None
        opt.follow_cue = follow_cue
        opt.follow_bands = NULL if c_bands is None else &c_bands[0, 0]
        opt.follow_n_bands = 0 if c_bands is None else c_bands.shape[1]
        opt.follow_on_lost = follow_on_lost
        opt.on_silent_node = on_silent_node
        opt.max_overruns = max_overruns
        if opt.follow:
            if len(follow_options) != sizeof(mar_follow_options):
                free(c_axes)
                raise ArgumentError(f"follow_options must be {sizeof(mar_follow_options)} bytes")
            memcpy(&opt.follow_opt, <const char *>follow_options, sizeof(mar_follow_options))
        cdef int status = 0
        self.engine = mar_engine_create(&opt, c_axes, n_axes, &show[0, 0], show.shape[1],
                                        &loudness[0], NULL if c_onsets is None else &c_onsets[0],
                                        &status)
        free(c_axes)
        if self.engine == NULL:
            raise ArgumentError(f"the C engine refused its configuration (status {status})")
        self.loop = <mar_rtloop *>calloc(1, sizeof(mar_rtloop))
        if self.loop == NULL:
            raise MemoryError()
        self.n_axes = n_axes
        self.record_dtype = record_dtype(n_axes)
        if self.record_dtype.itemsize != mar_engine_record_size(self.engine):
            raise EngineError(f"record_dtype has {self.record_dtype.itemsize} bytes, the C "
                             f"record {mar_engine_record_size(self.engine)}: they must match")

    def __dealloc__(self):
        if self.loop != NULL:
            with nogil:
                mar_rt_stop(self.loop)
            free(self.loop)
        if self.engine != NULL:
            mar_engine_destroy(self.engine)

    def step(self, uint64_t n):
        """Run n ticks on the virtual clock; status code."""
        cdef int r
        with nogil:
            r = mar_engine_step(self.engine, n)
        return r

    def start(self, int priority, int cpu, bint lock_memory, uint64_t max_ticks):
        """Start the real-time loop; (status code, report dict)."""
        cdef mar_rt_options opt
        opt.priority = priority
        opt.cpu = cpu
        opt.lock_memory = lock_memory
        opt.max_ticks = max_ticks
        cdef int r
        with nogil:
            r = mar_rt_start(self.loop, self.engine, &opt)
        rep = self.loop.report
        return r, dict(fifo=bool(rep.fifo), fifo_error=rep.fifo_error, pinned=bool(rep.pinned),
                       pin_error=rep.pin_error, memory_locked=bool(rep.memory_locked),
                       lock_error=rep.lock_error)

    def stop(self):
        cdef int r
        with nogil:
            r = mar_rt_stop(self.loop)
        return r

    @property
    def running(self):
        """True while the real-time loop runs (False once it stopped by itself)."""
        return bool(self.loop.started) and not self.loop.finished

    def set_rate(self, double rate):
        return mar_engine_set_rate(self.engine, rate)

    def seek(self, double position):
        return mar_engine_seek(self.engine, position)

    def push_loudness(self, double value, double onset=NAN, bands=None):
        if bands is None:
            return mar_engine_push_frame(self.engine, value, onset)
        cdef double[::1] b = np.ascontiguousarray(bands, dtype=np.float64)
        if b.shape[0] == 0:
            return mar_engine_push_frame(self.engine, value, onset)
        return mar_engine_push_bands(self.engine, value, onset, &b[0], b.shape[0])

    def set_node_alarms(self, uint32_t alarms, uint32_t silent=0):
        """alarms: nodes silent or faulted (bit i: the i-th node); silent: those silent."""
        mar_engine_set_node_alarms(self.engine, alarms, silent)

    def source_lost(self):
        """The live source is lost: latched from the next tick (FLAG_SOURCE_LOST)."""
        mar_engine_source_lost(self.engine)

    def link_gone(self, int err):
        """The link's writes fail for good (err: an errno): every node silent
        from the next tick on (FLAG_LINK_LOST), as when the tick's own write() fails."""
        mar_sink_set_gone(mar_engine_sink(self.engine), err)

    def request(self, int kind, targets=None, bint synchronized=False):
        """Move request (REQUEST_*); targets: n_axes positions [unit] for REQUEST_GOTO."""
        cdef cnp.ndarray[cnp.float64_t, ndim=1, mode="c"] t = np.ascontiguousarray(
            np.full(self.n_axes, np.nan) if targets is None else targets, dtype=np.float64)
        if t.shape[0] != self.n_axes:
            raise ArgumentError(f"{t.shape[0]} targets for {self.n_axes} axes")
        return mar_engine_request(self.engine, kind, &t[0], synchronized)

    def set_sink(self, int kind, int fd, size_t ring_slots, int protocol=MAR_SINK_SERIAL):
        """Where setpoints go (SINK_*) and how they are encoded (PROTOCOL_*); status code."""
        return mar_sink_set(mar_engine_sink(self.engine), kind, fd, ring_slots, protocol)

    def set_poll(self, bint one_per_tick):
        """Serial: each SYNC polls one node in turn (True) or every node; status code."""
        return mar_sink_set_poll(mar_engine_sink(self.engine), one_per_tick)

    def snapshot(self):
        """(record as a one-element structured array, or None before the first tick)."""
        out = np.zeros(1, dtype=self.record_dtype)
        cdef cnp.ndarray buf = out.view(np.uint8)
        cdef uint8_t *p = <uint8_t *>cnp.PyArray_DATA(buf)
        cdef int r
        with nogil:
            r = mar_engine_snapshot(self.engine, <mar_record *>p, <double *>(p + sizeof(mar_record)))
        return out[0] if r == 0 else None

    def drain_records(self, size_t max_records=65536):
        """Flight-recorder records waiting in the ring, oldest first."""
        out = np.empty(max_records, dtype=self.record_dtype)
        cdef void *p = cnp.PyArray_DATA(out)
        cdef size_t n
        with nogil:
            n = mar_engine_drain_records(self.engine, p, max_records)
        return out[:n]

    def drain_frames(self, size_t max_frames=1024):
        """Encoded ticks waiting in the ring sink, as bytes, oldest first: serial
        frames, or CAN records (ext/mar_sink.h), one bytes object per tick."""
        cdef mar_sink *s = mar_engine_sink(self.engine)
        cdef size_t slot = sizeof(uint32_t) + s.frame_cap
        if s.ring.slot_size == 0:
            return []
        buf = np.empty(max_frames * slot, dtype=np.uint8)
        cdef uint8_t *p = <uint8_t *>cnp.PyArray_DATA(buf)
        cdef size_t n, i
        cdef uint32_t length
        with nogil:
            n = mar_ring_pop(&s.ring, p, max_frames)
        frames = []
        for i in range(n):
            memcpy(&length, p + i * slot, sizeof(uint32_t))
            frames.append(bytes(buf[i * slot + 4: i * slot + 4 + length]))
        return frames

    def counters(self):
        cdef mar_counters c
        mar_engine_counters(self.engine, &c)
        return c

    def quantiles(self, str which, qs):
        """Quantiles [ns] of the 'wake' or 'compute' histogram, then its count and max."""
        cdef const mar_hist *h = (mar_engine_wake_hist(self.engine) if which == "wake"
                                  else mar_engine_compute_hist(self.engine))
        return [mar_hist_quantile(h, q) for q in qs], mar_hist_count(h), mar_hist_max(h)

    def histogram(self, str which):
        """(bucket lower bounds [ns], widths [ns], counts, max [ns]) of the 'wake' or
        'compute' histogram, for merging runs."""
        cdef const mar_hist *h = (mar_engine_wake_hist(self.engine) if which == "wake"
                                  else mar_engine_compute_hist(self.engine))
        cdef int i
        lower = np.array([mar_hist_lower(i) for i in range(MAR_HIST_BINS)], dtype=np.int64)
        width = np.array([mar_hist_width(i) for i in range(MAR_HIST_BINS)], dtype=np.int64)
        counts = np.array([mar_hist_bin(h, i) for i in range(MAR_HIST_BINS)], dtype=np.uint64)
        return lower, width, counts, mar_hist_max(h)


def receiver_gone(int err):
    """True when a write's errno says the link is gone for good (ext/mar_sink.h)."""
    return mar_sink_receiver_gone(err) != 0


def plan_move(double x0, double v0, double target, double max_speed, double max_accel,
              times=None, duration=None):
    """An online move from position x0 [unit] and velocity v0 [unit/s] to
    target at rest: time-optimal, or lasting exactly duration [s] when given.
    Returns (duration [s], ok, positions, velocities) with the profile
    sampled at times [s] (empty arrays without times); ok is False when the
    timed profile was impossible and the time-optimal one was used."""
    cdef mar_move m
    cdef int status = 0
    if duration is None:
        mar_move_plan(&m, x0, v0, target, max_speed, max_accel)
    else:
        status = mar_move_plan_timed(&m, x0, v0, target, max_speed, max_accel, duration)
    cdef cnp.ndarray[cnp.float64_t, ndim=1, mode="c"] t = np.ascontiguousarray(
        [] if times is None else times, dtype=np.float64)
    cdef cnp.ndarray[cnp.float64_t, ndim=1, mode="c"] x = np.empty(t.shape[0])
    cdef cnp.ndarray[cnp.float64_t, ndim=1, mode="c"] v = np.empty(t.shape[0])
    cdef Py_ssize_t i
    for i in range(t.shape[0]):
        x[i] = mar_move_eval(&m, t[i], &v[i])
    return mar_move_duration(&m), status == 0, x, v


def move_durations(double[::1] x0, double[::1] v0, double[::1] target, double[::1] max_speed,
                   double[::1] max_accel):
    """Time-optimal durations [s] of many moves at once (for benchmarks)."""
    cdef Py_ssize_t n = x0.shape[0], i
    out = np.empty(n)
    cdef double[::1] d = out
    cdef mar_move m
    with nogil:
        for i in range(n):
            d[i] = mar_move_plan(&m, x0[i], v0[i], target[i], max_speed[i], max_accel[i])
    return out
