# Declarations of the plain-C engine in ext/ (the protocol codec it uses is
# declared in _cprotocol.pxd). Declarations only: the binding is _core.pyx.
from libc.stdint cimport int32_t, int64_t, uint8_t, uint32_t, uint64_t


cdef extern from "mar_hist.h" nogil:
    enum:
        MAR_HIST_BINS
    ctypedef struct mar_hist:
        pass
    uint64_t mar_hist_bin(const mar_hist *h, int index)
    int64_t mar_hist_lower(int index)
    int64_t mar_hist_width(int index)
    int64_t mar_hist_quantile(const mar_hist *h, double q)
    uint64_t mar_hist_count(const mar_hist *h)
    int64_t mar_hist_max(const mar_hist *h)


cdef extern from "mar_limits.h" nogil:
    ctypedef struct mar_limits:
        double pos_min
        double pos_max
        double max_speed
        double max_accel


cdef extern from "mar_sink.h" nogil:
    enum:
        MAR_SINK_NONE
        MAR_SINK_FD
        MAR_SINK_RING
        MAR_SINK_SERIAL
        MAR_SINK_CAN
        MAR_CAN_RECORD_BYTES
    ctypedef struct mar_axis_address:
        uint8_t node
        uint8_t channel
        double scale
        double offset
    ctypedef struct mar_ring:
        size_t slot_size
    ctypedef struct mar_sink:
        mar_ring ring
        size_t frame_cap
    int mar_sink_set(mar_sink *s, int kind, int fd, size_t ring_slots, int protocol)
    int mar_sink_set_poll(mar_sink *s, int one_per_tick)
    int mar_sink_receiver_gone(int err)
    void mar_sink_set_gone(mar_sink *s, int err)
    size_t mar_ring_pop(mar_ring *r, void *dst, size_t max_items)


cdef extern from "mar_move.h" nogil:
    ctypedef struct mar_move:
        double target
    double mar_move_plan(mar_move *m, double x0, double v0, double target, double vmax, double amax)
    int mar_move_plan_timed(mar_move *m, double x0, double v0, double target, double vmax,
                            double amax, double duration)
    double mar_move_duration(const mar_move *m)
    double mar_move_eval(const mar_move *m, double t, double *v)


cdef extern from "mar_follow.h" nogil:
    ctypedef struct mar_follow_options:     # filled by marionette._follow (options_bytes)
        pass


cdef extern from "mar_engine.h" nogil:
    enum:
        MAR_FLAG_LIMITED
        MAR_FLAG_END
        MAR_FLAG_BAD_INPUT
        MAR_FLAG_MOVING
        MAR_FLAG_HOLDING
        MAR_FLAG_UNFOLLOWED
        MAR_FLAG_SOURCE_LOST
        MAR_FLAG_NODE_SILENT
        MAR_FLAG_FAULT_STOP
        MAR_FLAG_FAULT_HOLD
        MAR_FLAG_OVERRUNS
        MAR_FLAG_LINK_LOST
        MAR_FLAG_STOPPING
    enum mar_fault_reaction:
        MAR_FAULT_CONTINUE
        MAR_FAULT_STOP
        MAR_FAULT_HOLD
        MAR_FAULT_ESTOP
    ctypedef struct mar_axis:
        mar_limits limits
        double dead_time
        double time_constant
        double start
        mar_axis_address address
    ctypedef struct mar_engine_options:
        double period
        int lead_mode
        int interp
        size_t record_slots
        size_t loudness_slots
        int start_holding
        int follow
        mar_follow_options follow_opt
        double follow_cue
        const double *follow_bands
        size_t follow_n_bands
        int follow_on_lost
        int on_silent_node
        uint64_t max_overruns
    ctypedef struct mar_record:
        int64_t tick
        int64_t time_ns
        double position
        double rate
        double live_loudness
        double stored_loudness
        double follow_confidence
        uint32_t flags
        uint32_t limited_axes
        int32_t follow_state
        uint32_t node_alarms
    ctypedef struct mar_counters:
        uint64_t ticks
        uint64_t overruns
        uint64_t limited
        uint64_t bad_input
        uint64_t records_dropped
        uint64_t loudness_dropped
        uint64_t sink_frames
        uint64_t sink_errors
        uint64_t sink_bytes
    ctypedef struct mar_engine:
        pass
    mar_engine *mar_engine_create(const mar_engine_options *opt, const mar_axis *axes, size_t n_axes,
                                  const double *show, size_t n_ticks, const double *loudness,
                                  const double *onsets, int *status)
    void mar_engine_destroy(mar_engine *e)
    int mar_engine_step(mar_engine *e, uint64_t n)
    int mar_engine_set_rate(mar_engine *e, double rate)
    int mar_engine_seek(mar_engine *e, double position)
    int mar_engine_push_loudness(mar_engine *e, double value)
    int mar_engine_push_frame(mar_engine *e, double value, double onset)
    int mar_engine_push_bands(mar_engine *e, double value, double onset, const double *bands, size_t n_bands)
    void mar_engine_set_node_alarms(mar_engine *e, uint32_t alarms, uint32_t silent)
    void mar_engine_source_lost(mar_engine *e)
    int mar_engine_request(mar_engine *e, int kind, const double *targets, int synchronized)
    int mar_engine_snapshot(const mar_engine *e, mar_record *rec, double *commands)
    size_t mar_engine_record_size(const mar_engine *e)
    size_t mar_engine_drain_records(mar_engine *e, void *dst, size_t max)
    mar_sink *mar_engine_sink(mar_engine *e)
    void mar_engine_counters(const mar_engine *e, mar_counters *c)
    const mar_hist *mar_engine_wake_hist(const mar_engine *e)
    const mar_hist *mar_engine_compute_hist(const mar_engine *e)


cdef extern from "mar_rtloop.h" nogil:
    ctypedef struct mar_rt_options:
        int priority
        int cpu
        int lock_memory
        uint64_t max_ticks
    ctypedef struct mar_rt_report:
        int fifo
        int fifo_error
        int pinned
        int pin_error
        int memory_locked
        int lock_error
    ctypedef struct mar_rtloop:
        mar_rt_report report
        int finished
        int started
    int mar_rt_start(mar_rtloop *loop, mar_engine *e, const mar_rt_options *opt)
    int mar_rt_stop(mar_rtloop *loop)
