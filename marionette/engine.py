"""The Python face of the C tick engine.

    config = marionette.load_config()              # the bundled figure
    show = marionette.load_show("dance.csv", config)
    with marionette.Engine(config, show, record="flight.bin") as engine:
        engine.start()                             # real-time loop, 20 ms grid
        ...
        print(engine.stats())

or ``engine.step(n)`` for n ticks on a virtual clock (tests, offline tools).
"""
from __future__ import annotations

import errno
import math
import os
import threading
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from marionette import _core
from marionette.config import FigureConfig
from marionette.errors import ArgumentError, EngineError
from marionette.music.follower import (DEFAULT_START, STATES as _FOLLOW_STATE_NAMES, cue_ticks,
                                       engine_options as follower_options, stored_bands)
from marionette.music.node_source import NodeLoudness
from marionette.recorder import FlightRecorder
from marionette.show import Show, fit_to_figure
from marionette.transport.supervisor import LinkSupervisor

LEAD_MODES = {"dead_time_lag": _core.LEAD_DEAD_TIME_LAG, "mean_delay": _core.LEAD_MEAN_DELAY,
              "none": _core.LEAD_NONE}
DEFAULT_LEAD = "dead_time_lag"      # play's and shape's default too
INTERPOLATIONS = {"cubic": _core.INTERP_CUBIC, "linear": _core.INTERP_LINEAR}
PROTOCOLS = {"serial": _core.PROTOCOL_SERIAL, "can": _core.PROTOCOL_CAN}
ON_LOST = {"flywheel": _core.ON_LOST_FLYWHEEL, "hold": _core.ON_LOST_HOLD}   # [follow] on_lost
SILENT_NODE = {"stop": _core.FAULT_STOP, "hold": _core.FAULT_HOLD, "estop": _core.FAULT_ESTOP,
               "continue": _core.FAULT_CONTINUE}                               # [faults] silent_node
CAN_COUNTS_MAX = 524287  # int20 counts of a CAN setpoint PDO (firmware_protocol/SPEC.md)
FOLLOW_STATES = dict(enumerate(_FOLLOW_STATE_NAMES))   # record follow_state -> name
RECORD_SLOTS = 4096      # flight-recorder ring [ticks], 82 s at 20 ms
LOUDNESS_SLOTS = 256     # live loudness input ring [frames]
FRAME_SLOTS = 256        # setpoint frames waiting for the Python sender [ticks]
DRAIN_INTERVAL = 0.05    # how often the Python threads empty the rings [s]
SEND_INTERVAL = 0.001    # ... and the frame ring, for a link without a descriptor [s]
MAX_RATE = 10.0          # playback rate bound [show ticks per tick]
END_ACTIONS = (None, "hold", "home")   # Engine(end=...): at the end of a real-time run on a link
SETTLE_TAUS = 5          # the servos are at rest this many time constants after their dead time


def _raise_for(status: int, what: str) -> None:
    if status < 0:
        raise EngineError(f"{what}: {os.strerror(-status)} (status {status})")


@dataclass(frozen=True)
class Snapshot:
    """A consistent copy of the latest tick."""

    tick: int
    time_s: float            # scheduled tick time [s]
    position: float          # playback position [show ticks]
    rate: float              # playback rate [show ticks per tick]
    live_loudness: float     # newest live loudness, NaN when none came
    stored_loudness: float   # taught loudness at the position
    flags: int               # marionette._core.FLAG_*
    commands: dict           # axis name -> command [unit]
    follow_state: str | None  # the music follower's state, None without one
    follow_confidence: float  # its confidence [0, 1], NaN without one
    node_alarms: int         # bit i: the i-th servo node (ascending) is silent or faulted


def axis_table(config: FigureConfig, start: np.ndarray) -> np.ndarray:
    """The figure's axes as the C engine takes them (marionette._core.AXIS_DTYPE)."""
    axes = np.zeros(len(config.axes), dtype=_core.AXIS_DTYPE)
    for j, a in enumerate(config.axes):
        axes[j] = (a.min, a.max, a.max_speed, a.max_accel, a.dead_time, a.time_constant,
                   start[j], a.node, a.channel, a.scale, a.offset)
    return axes


class Engine:
    """Plays a show on a figure: the C tick, in real time or in steps.

    lead: "dead_time_lag" (default: x(t+Td) + tau*x'(t+Td)), "mean_delay"
    (the paper: x(t+Td+tau)) or "none". interpolation: "cubic" or "linear".
    output: where setpoints go: None; a file descriptor or an object with
    fileno() (the tick writes to it itself, no GIL); or any object with
    write(bytes) (a Python thread drains a ring into it). protocol: how
    setpoints are encoded (firmware_protocol/SPEC.md): "serial" (default:
    per tick a SYNC and SETPOINT frames, COBS-framed) or "can" (per tick the
    SYNC and setpoint PDO frames, as 16-byte struct can_frame records; see
    marionette.protocol.can_records). record: None,
    True (keep records in memory) or a file path (flight record).
    start_pose: where the figure stands, at rest, when the engine is made:
    None (default) means at the show's first pose, and the show plays from
    the first tick; "home" or a pose {axis: position} means there, holding,
    until blend_in() moves it into the show. follow: "smooth", "paper" or
    True (the figure's [follow] mode) to let the live music drive the show
    (push_loudness), None to let the rate drive it. follow_start: where in
    the show's music the live music starts [s] (a cue; default 0, the top:
    follow.DEFAULT_START): the show waits there through the silence before
    the music and plays from the music's onset (mar_follow_cue); None:
    unknown, the follower searches the whole piece.
    on_lost: what the show does while the music is not followed (the
    follower searches after it had a place; the records' FLAG_UNFOLLOWED):
    "flywheel" (play on at the last rate) or "hold" (stand at the place
    where it was lost, then blend back in); None: the figure's [follow] on_lost.
    end: what a real-time run on a link does when it reaches max_ticks (the
    end of the show): None (default) stops sending there, and the nodes'
    watchdogs stop the figure; "hold" brings it to rest where braking ends
    (the last pose, for a show that ends at rest), "home" makes a limited
    move home; either way the engine holds until the servos have played out
    their dead time and lag, then stops and tells the nodes (ESTOP, then
    ESTOP_RELEASE: they hold where they stand, PRE_OPERATIONAL, watchdog
    disarmed until the next setpoint), so no watchdog trips (wait()).
    The figure's [faults] table sets what the tick does when a servo node
    falls silent and how many real-time overruns stop the show (records'
    FLAG_NODE_SILENT, FLAG_FAULT_STOP, FLAG_FAULT_HOLD, FLAG_OVERRUNS); a
    fault that stops the show ends a run with an end action there, as the
    end of the show would (wait()).
    """

    def __init__(self, config: FigureConfig, show: Show, *, lead: str = DEFAULT_LEAD,
                 interpolation: str = "cubic", output=None, protocol: str | None = None,
                 record=None, rate: float = 1.0, on_limits: str = "error", start_pose=None,
                 follow: str | None = None, poll: str = "all", follow_start: float | None = DEFAULT_START,
                 on_lost: str | None = None, end: str | None = None):
        if end not in END_ACTIONS:
            raise ArgumentError(f"end must be one of {END_ACTIONS}, not {end!r}")
        self.end = end
        self._end_thread: threading.Thread | None = None
        self._rested = threading.Event()
        self._estopped = False              # the operator's e-stop holds the nodes latched
        self._until_show_end = False        # start(until_show_end=True): the show's end ends the run
        self._cancel_end = threading.Event()
        if lead not in LEAD_MODES:
            raise ArgumentError(f"lead must be one of {sorted(LEAD_MODES)}, not {lead!r}")
        if interpolation not in INTERPOLATIONS:
            raise ArgumentError(f"interpolation must be one of {sorted(INTERPOLATIONS)}, "
                                f"not {interpolation!r}")
        on_lost = config.follow.on_lost if on_lost is None else on_lost
        if on_lost not in ON_LOST:
            raise ArgumentError(f"on_lost must be one of {sorted(ON_LOST)}, not {on_lost!r}")
        protocol = protocol or getattr(output, "protocol", "serial")
        if protocol not in PROTOCOLS:
            raise ArgumentError(f"protocol must be one of {sorted(PROTOCOLS)}, not {protocol!r}")
        self.protocol = protocol
        self.config = config
        self.show = fit_to_figure(show, config, on_limits)
        positions = np.ascontiguousarray(self.show.positions, dtype=np.float64)
        cue = float("nan") if follow is None else cue_ticks(follow_start, self.show.n_ticks,
                                                            config.tick_period, "follow_start")
        first = 0 if math.isnan(cue) else min(int(round(cue)), positions.shape[1] - 1)
        start = positions[:, first] if start_pose is None else self._pose(start_pose, fill=None)
        self.follow = follow
        # the stored band levels the follower correlates (None: the loudness alone)
        bands = (None if follow is None or self.show.bands is None
                 else stored_bands(self.show.bands, self.show.n_ticks, f"{self.show.path}: bands"))
        self.follow_bands = 0 if bands is None else bands.shape[1]     # band levels per frame
        self._core = _core.CoreEngine(
            config.tick_period, LEAD_MODES[lead], INTERPOLATIONS[interpolation],
            axis_table(config, start), positions,
            np.ascontiguousarray(self.show.loudness, dtype=np.float64),
            RECORD_SLOTS if record else 0, LOUDNESS_SLOTS, start_pose is not None,
            None if follow is None else follower_options(config, self.show, follow),
            self.show.onsets if follow is not None else None, cue, ON_LOST[on_lost],
            SILENT_NODE[config.faults.silent_node], config.faults.overruns, bands)
        self._request_lock = threading.Lock()
        self.recorder = None
        if record:
            path = None if record is True else Path(record)
            meta = dict(figure=config.name, config=config.source, show=self.show.path,
                        tick_period=config.tick_period, lead=lead, interpolation=interpolation)
            self.recorder = FlightRecorder(self._core.record_dtype, config.axis_names, path, meta)
        self._writer = None
        self._attach_output(output)
        if poll not in ("all", "one"):
            raise ArgumentError(f"poll must be 'all' or 'one', not {poll!r}")
        if poll == "one":
            if self.protocol != "serial":
                raise ArgumentError("poll='one' is for a serial line; a CAN SYNC polls every node")
            _raise_for(self._core.set_poll(True), "poll")
        # the servo nodes' LOUDNESS as a live source, when the music is followed
        self.node_loudness = NodeLoudness(self.push_loudness).start() if follow else None
        self.supervisor = None      # the servo nodes' receive path, for a link (marionette.transport)
        if hasattr(output, "start_receiving"):
            self.supervisor = LinkSupervisor(
                output, config, self._latest_tick, self._core.set_node_alarms, poll == "one",
                on_loudness=None if self.node_loudness is None else self.node_loudness.take,
                log_path=None if record in (None, False, True) else f"{record}.nodes.csv")
        self.set_rate(rate)
        self._drain_thread: threading.Thread | None = None
        self._stop_drain = threading.Event()
        self.report: dict = {}
        self.source_lost_reason: str | None = None     # the first source_lost()'s reason

    def _check_addresses(self) -> None:
        """Every axis must be addressable by the protocol (the C sink refuses
        otherwise; this says which axis and why)."""
        for a in self.config.axes:
            if self.protocol == "serial" and a.node == 255:
                raise ArgumentError(f"axis {a.name!r}: node 255 is the broadcast address of the "
                                    f"serial protocol; use nodes 0..254")
            if self.protocol == "can":
                if not 1 <= a.node <= 127 or a.channel > 8:
                    raise ArgumentError(f"axis {a.name!r}: node {a.node}, channel {a.channel} cannot be "
                                        f"carried on CAN (nodes 1..127, channels 0..8)")
                reach = max(abs(a.offset + a.scale * a.min), abs(a.offset + a.scale * a.max))
                if reach > CAN_COUNTS_MAX:
                    raise ArgumentError(f"axis {a.name!r}: its limits reach {reach:.0f} counts; CAN "
                                        f"setpoints carry at most +-{CAN_COUNTS_MAX} (smaller scale, or serial)")

    def _attach_output(self, output) -> None:
        if output is None:
            return
        self._check_addresses()
        protocol = PROTOCOLS[self.protocol]
        fd = output if isinstance(output, int) else getattr(output, "fileno", None)
        if callable(fd):
            try:
                fd = fd()
            except (OSError, ValueError):   # e.g. io objects without a descriptor
                fd = None
        if isinstance(fd, int):
            os.set_blocking(fd, False)      # the tick must never block in write()
            _raise_for(self._core.set_sink(_core.SINK_FD, fd, 0, protocol), "attaching the output")
        elif hasattr(output, "write"):
            _raise_for(self._core.set_sink(_core.SINK_RING, -1, FRAME_SLOTS, protocol),
                       "attaching the output")
            self._writer = output
        else:
            raise TypeError(f"output must be a file descriptor, have fileno() or write(), "
                            f"not {type(output).__name__}")

    # -- running ---------------------------------------------------------

    def step(self, n: int = 1) -> None:
        """Run n ticks on the virtual clock, as fast as the CPU allows."""
        if n < 0:
            raise ArgumentError(f"cannot step {n} ticks")
        chunk = RECORD_SLOTS // 2
        while n > 0:
            k = min(n, chunk)
            status = self._core.step(k)
            if status == -errno.EBUSY:
                raise EngineError("step(): the real-time loop is running; stop() it first")
            _raise_for(status, "step")
            self._drain()
            n -= k

    def start(self, *, priority: int = 80, cpu: int | None = None, lock_memory: bool = False,
              max_ticks: int = 0, until_show_end: bool = False) -> dict:
        """Start the real-time loop (SCHED_FIFO at priority when permitted).

        Returns what was granted; warns when FIFO, pinning or memory locking
        was refused. max_ticks > 0 makes the loop stop by itself;
        until_show_end: it stops at the show's end (FLAG_END) too, which a
        show following slow music reaches after more ticks than it has."""
        if not 0 <= priority <= 99:
            raise ArgumentError(f"priority must be 0..99, not {priority}")
        self._until_show_end = until_show_end
        safe_end = self.end is not None and self.supervisor is not None and max_ticks > 0
        status, report = self._core.start(priority, -1 if cpu is None else cpu,
                                          lock_memory, 0 if safe_end else max_ticks)
        if status == -errno.EBUSY:
            raise EngineError("start(): the real-time loop is already running")
        _raise_for(status, "starting the real-time loop")
        refused = []
        if priority and not report["fifo"]:
            refused.append(f"SCHED_FIFO priority {priority} ({os.strerror(report['fifo_error'])})")
        if cpu is not None and not report["pinned"]:
            refused.append(f"pinning to CPU {cpu} ({os.strerror(report['pin_error'])})")
        if lock_memory and not report["memory_locked"]:
            refused.append(f"mlockall ({os.strerror(report['lock_error'])})")
        if refused:
            warnings.warn("real-time loop runs without " + ", ".join(refused)
                          + "; timing will be less regular", RuntimeWarning, stacklevel=2)
        self.report = report
        self._stop_drain.clear()
        self._drain_thread = threading.Thread(target=self._drain_loop, name="marionette-drain",
                                              daemon=True)
        self._drain_thread.start()
        if self.supervisor is not None:
            self.supervisor.start()
        if safe_end:
            self._rested.clear()
            self._cancel_end.clear()
            self._end_thread = threading.Thread(target=self._come_to_rest, args=(max_ticks,),
                                                name="marionette-end", daemon=True)
            self._end_thread.start()
        return report

    def _come_to_rest(self, last_tick: int) -> None:
        """At tick last_tick - 1: the end action, then hold until the servos
        have played out their dead time and lag; then _rested is set."""
        def until(ready) -> bool:
            while not self._cancel_end.wait(0.005):
                rec = self._core.snapshot()
                if rec is not None and ready(rec):
                    return True
            return False
        def fault(rec) -> bool:         # a fault reaction stopped the show: it ends there
            return bool(rec["flags"] & _core.FLAG_FAULT_STOP)
        if not until(lambda rec: int(rec["tick"]) >= last_tick - 1 or fault(rec) or self._at_show_end(rec)):
            return
        if not fault(self._core.snapshot()):
            if self.end == "home":
                self.home()
            else:
                self.stop_motion()
        seen = self._latest_tick()
        if not until(lambda rec: int(rec["tick"]) > seen + 1 and rec["flags"] & _core.FLAG_HOLDING):
            return
        settle = max(a.dead_time + SETTLE_TAUS * a.time_constant for a in self.config.axes)
        if not self._cancel_end.wait(settle + 2 * self.config.tick_period):
            self._rested.set()

    def _at_show_end(self, rec) -> bool:
        return self._until_show_end and bool(rec["flags"] & _core.FLAG_END)

    def _fault_stopped(self, rec) -> bool:
        """Running until the show's end, a fault reaction stopped the show and
        the figure holds: the latch keeps the show from going on, so its end
        would never come and the run ends here. (With max_ticks alone the run
        goes on to them, holding.)"""
        flags = rec["flags"]
        return (self._until_show_end and bool(flags & _core.FLAG_FAULT_STOP)
                and bool(flags & _core.FLAG_HOLDING))

    @property
    def running(self) -> bool:
        return self._core.running

    def stop(self) -> None:
        """Stop the real-time loop and drain what it left in the rings. A
        figure stopped at rest on a link (an operator's controlled stop)
        leaves its nodes told, as at the show's end; an e-stopped one stays
        latched."""
        if self._end_thread is not None:       # stopped before the end came: no end action
            self._cancel_end.set()
            self._end_thread.join()
            self._end_thread = None
        snap = self._core.snapshot() if self.supervisor is not None and self._core.running else None
        at_rest = snap is not None and bool(snap["flags"] & _core.FLAG_HOLDING) and not self._estopped
        _raise_for(self._core.stop(), "stopping the real-time loop")
        if at_rest:
            self._tell_nodes_at_rest()
        if self.supervisor is not None:
            self.supervisor.stop()
        self._stop_drain.set()
        if self._drain_thread is not None:
            self._drain_thread.join()
            self._drain_thread = None
        self._drain()

    def _tell_nodes_at_rest(self) -> None:
        """The loop stopped with the figure at rest: ESTOP (the quick stop
        moves nothing), then a release, so the nodes hold with no watchdog
        to trip; the "estop" fault reaction leaves them latched."""
        try:
            self.supervisor.estop()
            if not self.supervisor.estop_sent:
                time.sleep(2 * self.config.tick_period)
                self.supervisor.release()
        except OSError:                     # the link is gone (its nodes' watchdogs stop them)
            pass

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until the loop stops by itself (max_ticks; with until_show_end
        the show's end, or a fault reaction's stop once the figure holds);
        True if it did. With end="hold" or "home" on a link: until the figure
        has come to rest after max_ticks; then the loop stops and the nodes
        are told."""
        if self._end_thread is not None:
            if not self._rested.wait(timeout):
                return False
            _raise_for(self._core.stop(), "stopping the real-time loop")
            self._tell_nodes_at_rest()
            self._end_thread.join()
            self._end_thread = None
            return True
        end = None if timeout is None else time.monotonic() + timeout
        while self._core.running:
            rec = self._core.snapshot()
            if rec is not None and (self._at_show_end(rec) or self._fault_stopped(rec)):
                _raise_for(self._core.stop(), "stopping the real-time loop")
                return True
            if end is not None and time.monotonic() >= end:
                return False
            time.sleep(0.01)
        return True

    def close(self) -> None:
        self.stop()
        if self.node_loudness is not None:
            self.node_loudness.stop()
        if self.supervisor is not None:
            self.supervisor.close()
        if self.recorder is not None:
            self.recorder.close()

    def __enter__(self) -> Engine:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _drain(self) -> None:
        if self.recorder is not None:
            while True:
                records = self._core.drain_records(RECORD_SLOTS)
                self.recorder.add(records)
                if len(records) < RECORD_SLOTS:
                    break
        if self._writer is not None:
            for frame in self._core.drain_frames(FRAME_SLOTS):
                self._writer.write(frame)
            gone = getattr(self._writer, "gone", 0)     # a link whose writes fail for good (CanLink)
            if gone:
                self._core.link_gone(gone)

    def _drain_loop(self) -> None:
        # Waits on the event between drains, so stop() wakes it at once.
        interval = DRAIN_INTERVAL if self._writer is None else SEND_INTERVAL
        while not self._stop_drain.wait(interval):
            self._drain()

    # -- commands and readings -------------------------------------------

    def set_rate(self, rate: float) -> None:
        """Playback rate [show ticks per tick]; 1 plays as taught, 0 holds."""
        if not (0.0 <= rate <= MAX_RATE):
            raise ArgumentError(f"rate {rate!r} is outside [0, {MAX_RATE}] show ticks per tick")
        _raise_for(self._core.set_rate(float(rate)), "set_rate")

    def seek(self, position: float) -> None:
        """Jump the playback position [show ticks]; the hard limits smooth the jump."""
        if not (0.0 <= position <= self.show.n_ticks - 1):
            raise ArgumentError(f"position {position!r} is outside [0, {self.show.n_ticks - 1}] ticks")
        _raise_for(self._core.seek(float(position)), "seek")

    def _latest_tick(self) -> int | None:
        rec = self._core.snapshot()
        return None if rec is None else int(rec["tick"])

    @property
    def nodes(self):
        """What the receive path knows of each servo node (a NodeMonitor), or None without a link."""
        return None if self.supervisor is None else self.supervisor.nodes

    def estop(self) -> None:
        """E-stop: every node latches and brakes to rest (ESTOP), and the
        engine's own commands ramp to rest too (stop_motion)."""
        self.stop_motion()
        self._estopped = True
        if self.supervisor is not None:
            self.supervisor.estop()

    def release_estop(self) -> None:
        """Release the nodes' e-stop latch; they hold where they stopped.
        blend_in() then moves the figure back into the show."""
        self._estopped = False
        if self.supervisor is not None:
            self.supervisor.release()

    def source_lost(self, reason: str) -> None:
        """The live music's source is lost (a sound card's stream failed or
        ended, or no frames came): from the next tick to the end every record
        carries FLAG_SOURCE_LOST and the music is not followed (FLAG_UNFOLLOWED;
        on_lost applies at once: the show plays on at the last rate, or holds),
        whatever frames come later (docs/music.md). From any thread; the
        first reason is kept in source_lost_reason, later calls change nothing."""
        if self.source_lost_reason is None:
            self.source_lost_reason = str(reason)
        self._core.source_lost()

    def push_loudness(self, value: float, onset: float = float("nan"), bands=None) -> None:
        """Hand the tick a live loudness frame (>= 0, finite), its onset
        strength [dB] (>= 0; NaN: the source has none, as a node's LOUDNESS)
        and its band levels [full scale] (marionette.music.bands; None: the
        source has none); refused frames raise. A show with stored onsets
        lets the follower place its tracking peak on them; a show with
        stored bands correlates the bands of frames that bring as many
        (follow_bands); other frames count with their loudness alone."""
        if bands is not None and len(bands) != self.follow_bands:
            bands = None
        status = self._core.push_loudness(float(value), float(onset), bands)
        if status == -errno.EINVAL:
            raise ArgumentError(f"live frame {value!r} (onset {onset!r}, bands {bands!r}) refused: the "
                                "loudness must be finite and >= 0, the onset NaN or finite and >= 0, "
                                "each band level finite and >= 0")
        _raise_for(status, "push_loudness")

    def _pose(self, pose, fill) -> np.ndarray:
        """A pose [unit] per axis from "home" or {axis: position}; axes not
        named get fill (None: every axis must be named)."""
        if isinstance(pose, str):
            if pose != "home":
                raise ArgumentError(f"unknown pose {pose!r} (use 'home' or a mapping axis -> position)")
            pose = {a.name: a.home for a in self.config.axes}
        unknown = set(pose) - set(self.config.axis_names)
        if unknown:
            raise ArgumentError(f"pose names unknown axis {sorted(unknown)[0]!r} "
                                f"(known: {', '.join(self.config.axis_names)})")
        out = np.empty(len(self.config.axes))
        for j, axis in enumerate(self.config.axes):
            if axis.name not in pose:
                if fill is None:
                    raise ArgumentError(f"pose has no position for axis {axis.name!r}")
                out[j] = fill
                continue
            x = float(pose[axis.name])
            if not axis.min <= x <= axis.max:
                raise ArgumentError(f"pose: axis {axis.name!r} position {x!r} {axis.unit} is outside "
                                    f"its limits [{axis.min!r}, {axis.max!r}]")
            out[j] = x
        return out

    def _request(self, kind: int, targets=None, synchronized: bool = False) -> None:
        with self._request_lock:
            _raise_for(self._core.request(kind, targets, synchronized), "move request")

    def move_to(self, pose, *, synchronized: bool = False) -> None:
        """Move to a pose ("home" or {axis: position [unit]}) by time-optimal
        limited moves from wherever the figure is, then hold. Axes left out
        stop where their braking ends. synchronized: all axes arrive
        together. Calling again while moving re-plans from the present state."""
        self._request(_core.REQUEST_GOTO, self._pose(pose, fill=np.nan), synchronized)

    def home(self, *, synchronized: bool = True) -> None:
        """move_to("home")."""
        self.move_to("home", synchronized=synchronized)

    def blend_in(self, position: float | None = None, *, synchronized: bool = True) -> None:
        """Move from wherever the figure is to the show's pose at position
        [show ticks] (default: where playback stands), then play from there."""
        if position is not None:
            self.seek(position)
        self._request(_core.REQUEST_BLEND, None, synchronized)

    def stop_motion(self) -> None:
        """Decelerate every axis to rest at its acceleration limit (the e-stop
        ramp; also aborts a move), then hold: each drive brakes from where
        the commands already sent will have taken it (docs/architecture.md,
        Stops). blend_in() resumes the show."""
        self._request(_core.REQUEST_STOP)

    def snapshot(self) -> Snapshot | None:
        """The latest tick, consistent across all axes; None before the first tick."""
        rec = self._core.snapshot()
        if rec is None:
            return None
        return Snapshot(tick=int(rec["tick"]), time_s=int(rec["time_ns"]) * 1e-9,
                        position=float(rec["position"]), rate=float(rec["rate"]),
                        live_loudness=float(rec["live_loudness"]),
                        stored_loudness=float(rec["stored_loudness"]), flags=int(rec["flags"]),
                        commands=dict(zip(self.config.axis_names, map(float, rec["command"]))),
                        follow_state=FOLLOW_STATES.get(int(rec["follow_state"])),
                        follow_confidence=float(rec["follow_confidence"]),
                        node_alarms=int(rec["node_alarms"]))

    def records(self) -> np.ndarray:
        """Flight-recorder records so far (requires record=...)."""
        if self.recorder is None:
            raise EngineError("records(): this engine was made without record=")
        self._drain()
        return self.recorder.records()

    def histogram(self, which: str = "wake") -> tuple:
        """The 'wake' (latency) or 'compute' histogram: bucket lower bounds
        [ns], widths [ns], counts, and the exact maximum [ns]."""
        if which not in ("wake", "compute"):
            raise ArgumentError(f"histogram is 'wake' or 'compute', not {which!r}")
        return self._core.histogram(which)

    def stats(self) -> dict:
        """Counters, and wake-latency and compute-time percentiles [us]."""
        out = dict(self._core.counters())
        for which in ("wake", "compute"):
            (p50, p99, p999), count, peak = self._core.quantiles(which, (0.5, 0.99, 0.999))
            out[which] = dict(count=count, p50_us=p50 / 1e3, p99_us=p99 / 1e3,
                              p999_us=p999 / 1e3, max_us=peak / 1e3)
        if self.recorder is not None:
            out["recorded"] = self.recorder.count
        return out
