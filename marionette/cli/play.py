"""``marionette play [SHOW]``: play a show through the engine, in step mode
or in real time, to a file, a link to the servo nodes or nowhere, following
live music or not, and print a summary."""
from __future__ import annotations

import argparse
import os
import sys
from dataclasses import replace

import numpy as np

from marionette._core import FLAG_END
from marionette.cli.options import (PRIORITY, Number, figure_and_show, figure_args, input_file,
                                    output_file)
from marionette.cli.sync_sim import add_start_argument
from marionette.config import FOLLOW_MODES
from marionette.console import open_view
from marionette import limiter_report
from marionette.engine import DEFAULT_LEAD, FOLLOW_STATES, INTERPOLATIONS, LEAD_MODES, MAX_RATE, Engine
from marionette.errors import MarionetteError
from marionette.faults import FaultWatcher, summary as fault_summary
from marionette.music.report import (LostWatcher, choose_latency, follow_share, lost_events,
                                     never_locked_warning, recording_warnings, share_line,
                                     verdict_line)

PAUSE_ALLOWANCE_S = 600.0   # the operator's pauses may move a real-time show's end this much later [s]
TICKS = Number(int, 1)
RATE = Number(float, 0.0, MAX_RATE)
CPU = Number(int, 0, (os.cpu_count() or 1) - 1)


def register(sub) -> None:
    p = sub.add_parser("play", help="play a show through the engine and print a summary",
                       description="Play a show through the engine: in step mode (on a virtual "
                       "clock, as fast as the CPU allows) or in real time; to servo nodes (--link), "
                       "a file (--output) or nowhere; following live music (--music, "
                       "--audio-device) or not. Prints a summary; a flight record with --record.")
    figure_args(p)
    p.add_argument("--realtime", action="store_true",
                   help="run the real-time loop (default: step mode)")
    p.add_argument("--headless", action="store_true",
                   help="no live console: in real time one status line per second on stderr "
                        "(also whenever stdout is not a terminal; docs/console.md)")
    p.add_argument("--json", action="store_true", help="the status lines as JSON lines (headless)")
    p.add_argument("--ticks", type=TICKS,
                   help=f"ticks to run, {TICKS.range} (default: the whole show)")
    p.add_argument("--rate", type=RATE, default=1.0,
                   help=f"playback rate [show ticks per tick], {RATE.range} (default 1: as taught)")
    p.add_argument("--lead", choices=sorted(LEAD_MODES), default=DEFAULT_LEAD,
                   help="how far ahead each servo is sent its setpoint: dead_time_lag (default): "
                        "x(t + Td) + tau x'(t + Td), which cancels the dead time and the lag; "
                        "mean_delay: x(t + Td + tau), the paper's; none: x(t)")
    p.add_argument("--interpolation", choices=sorted(INTERPOLATIONS), default="cubic",
                   help="between the show's ticks: cubic (Catmull-Rom, default) or linear")
    p.add_argument("--priority", type=PRIORITY, default=80,
                   help=f"SCHED_FIFO priority {PRIORITY.range} (0: normal; default 80)")
    p.add_argument("--cpu", type=CPU, help=f"pin the real-time thread to this CPU, {CPU.range}")
    p.add_argument("--lock-memory", action=argparse.BooleanOptionalAction, default=True,
                   help="mlockall before starting the real-time loop (default; a warning, "
                        "not a failure, when not permitted)")
    p.add_argument("--end", choices=("hold", "home", "none"), default="hold",
                   help="at the end of a real-time show on a --link: come to rest and hold "
                        "(default), or a limited move home; then the nodes are told, so no "
                        "watchdog trips ('none': stop sending, the watchdogs stop the figure)")
    p.add_argument("--record", type=output_file, help="write the flight record to this file")
    p.add_argument("--output", type=output_file,
                   help="write the setpoint frames to this file or device")
    p.add_argument("--link", help="send to servo nodes: serial:URL[@BAUD] or "
                                  "can:INTERFACE:CHANNEL[@BITRATE] (see 'marionette sim')")
    p.add_argument("--follow", choices=FOLLOW_MODES,
                   help="follow the live music (default mode with --music or --audio-device: "
                        "the figure's [follow] table)")
    p.add_argument("--music", type=input_file,
                   help="the live music from this recording, played back as if live "
                        "(a silent or short one, or one never locked on, is warned about)")
    add_start_argument(p)
    p.add_argument("--audio-device", nargs="?", const="",
                   help="the live music from this sound card input (its index or a part of its "
                        "name, as listed when unknown; no value: the first input); needs the "
                        "'audio' extra. A lost input is reported at once and the exit status is 1")
    p.set_defaults(run=run)


def _recording_source(args, config, show):
    """The live music from --music (a recording played back as if live), or
    None; its sink is the engine, set once there is one. Band levels are
    measured when the show has them to follow."""
    if not args.music:
        return None
    from marionette.music.wav_source import WavSource
    return WavSource(args.music, period=config.tick_period, bands=show.bands is not None)


def _open_audio(args, engine_box: list, bands: bool):
    """The sound card source, started before the engine so that its input
    latency is known when the engine is made; frames go to the engine in
    engine_box once there is one (until then they are dropped)."""
    from marionette.music.sound_card import SoundCard
    audio = None

    def to_engine(value: float, onset: float, rows=None) -> None:
        if engine_box:
            engine_box[0].push_loudness(value, onset, rows)

    def audio_lost(reason: str) -> None:      # at once, from the source's watchdog
        print(f"audio input {audio.name!r} lost: {reason}", file=sys.stderr, flush=True)
        if engine_box:                        # the next tick on: not followed, flagged (latched)
            engine_box[0].source_lost(reason)

    # the index comes as a string: the source takes digits as an index
    audio = SoundCard(to_engine, device=args.audio_device or None, onsets=True, on_lost=audio_lost,
                      bands=bands)
    return audio.start()


def run(args) -> int:
    config, show = figure_and_show(args)
    period = config.tick_period                                         # [s]
    output = None
    if args.output and args.link:
        raise MarionetteError("give --output or --link, not both")
    live = _recording_source(args, config, show)
    follow = args.follow or (True if (live is not None or args.audio_device is not None) else None)
    # without --ticks, a show that follows music, or plays in real time, runs to its
    # end (FLAG_END): slow music, the operator's pauses (space) and --rate < 1 move the
    # end later than the show's ticks. The run's cap [ticks]: the show at its slowest
    # rate, plus a minute of waiting at the cue when following, plus PAUSE_ALLOWANCE_S
    # in real time
    until_end = args.ticks is None and (bool(follow) or args.realtime)
    n = args.ticks if args.ticks is not None else show.n_ticks
    if until_end:
        slowest = config.follow.rate_min if follow else args.rate                 # [1]
        n = int(np.ceil(show.n_ticks / slowest)) if slowest > 0 else show.n_ticks
        n += int(60.0 / period) * bool(follow) + int(PAUSE_ALLOWANCE_S / period) * args.realtime
        if live is not None:            # a recording: no longer than it lasts, no shorter than the show
            n = max(show.n_ticks, min(n, len(live.loudness) + 1))
    if live is not None:        # said before the show, which goes on regardless
        for line in recording_warnings(args.music, live.loudness, period, show.duration, args.start):
            print(line, file=sys.stderr, flush=True)
    if args.output:
        try:
            output = os.open(args.output, os.O_WRONLY | os.O_CREAT | os.O_NONBLOCK, 0o644)
        except OSError as exc:
            raise MarionetteError(f"--output {args.output}: cannot open it: {exc.strerror}") from None
    elif args.link:
        from marionette.transport import open_link
        output = open_link(args.link)
    audio, watcher, faults, engine_box = None, None, None, []
    view = None
    on_lost = config.follow.on_lost
    try:
        if args.audio_device is not None:
            audio = _open_audio(args, engine_box, show.bands is not None)
        latency, latency_from = choose_latency(config.follow.latency,
                                               audio.latency if audio is not None else None)
        config = replace(config, follow=replace(config.follow, latency=latency))
        with Engine(config, show, lead=args.lead, interpolation=args.interpolation,
                    output=output, record=args.record or True, rate=args.rate,
                    follow=follow, follow_start=args.start,
                    end=None if args.end == "none" else args.end) as engine:
            engine_box.append(engine)
            if audio is not None and audio.lost_reason is not None:     # lost before the engine was made
                engine.source_lost(audio.lost_reason)
            if live is not None:
                live.sink = engine.push_loudness
            view = open_view(args, engine)      # the live console or status lines, Ctrl-C
            if args.realtime:
                engine.start(priority=args.priority, cpu=args.cpu, lock_memory=args.lock_memory,
                             max_ticks=n, until_show_end=until_end)
                faults = FaultWatcher(engine, period).start()     # [faults]: told at once
                if follow:
                    watcher = LostWatcher(engine, period, on_lost).start()
                if live is not None:
                    live.start()
                view.wait()
                engine.stop()
                faults.stop()               # (again in finally when something raised: idempotent)
                if watcher is not None:
                    watcher.stop()
            elif live is not None:       # tick k has heard frame k - 1, as in sync-sim
                for k in range(n):
                    live.feed_tick(k)
                    view.step(1)
                    snap = engine.snapshot()
                    if until_end and snap is not None and snap.flags & FLAG_END:
                        break
            else:
                view.step(n)
            stats = engine.stats()
            records = engine.records()
            nodes = engine.nodes.summary() if engine.nodes is not None else None
    finally:
        if view is not None:
            view.close()
        if live is not None:
            live.stop()
        if watcher is not None:
            watcher.stop()
        if faults is not None:
            faults.stop()
        if audio is not None:
            audio.stop()
        if isinstance(output, int):
            os.close(output)
        elif output is not None:
            output.close()
    share = follow_share(records) if follow else None
    if follow and not args.realtime:     # the lines a real-time run prints as it happens
        for line in lost_events(records["flags"], records["position"], period, on_lost):
            print(line, file=sys.stderr)
    if share is not None and live is not None:      # a recording of another piece (or none)
        line = never_locked_warning(args.music, share)
        if line:
            print(line, file=sys.stderr, flush=True)
    mode = "real time" if args.realtime else "step mode"
    print(f"played {show.path} on {config.name} in {mode}: {stats['ticks']} ticks "
          f"({stats['ticks'] * period:.2f} s of show), lead {args.lead}, "
          f"{args.interpolation} interpolation, rate {args.rate:g}")
    for change in show.changes:
        print(f"  show changed: {change}")
    print(f"  flight recorder: {stats['recorded']} records, {stats['records_dropped']} dropped"
          + (f", written to {args.record}" if args.record else ""))
    print(f"  bad inputs refused: {stats['bad_input']}")
    limiter_report.print_summary(records, config, period, json_lines=args.json)
    if args.output or args.link:
        print(f"  output {args.output or args.link}: {stats['sink_frames']} ticks sent, "
              f"{stats['sink_bytes']} bytes, {stats['sink_errors']} lost")
    if nodes is not None:
        print(f"  servo nodes: {nodes['frames_ok']} frames back, {nodes['frames_bad']} refused")
        for node, s in nodes["nodes"].items():
            print(f"    node {node}: {s['statuses']} statuses, last tick {s['last_tick']}, "
                  f"flags 0x{s['flags']:02x}, {s['errors']} errors"
                  + (", SILENT" if s["silent"] else ""))
    if follow:
        states = records["follow_state"]
        shares = ", ".join(f"{name} {np.mean(states == code):.0%}"
                           for code, name in FOLLOW_STATES.items())
        print(f"  music follower ({args.follow or config.follow.mode}): {shares}; "
              f"position at the end {records['position'][-1]:.1f} ticks, "
              f"rate {records['rate'][-1]:.3f}; input latency {latency * 1e3:.0f} ms ({latency_from})")
        print(share_line(share, period, on_lost))
    c = stats["compute"]
    print(f"  tick compute [us]: p50 {c['p50_us']:.2f}  p99 {c['p99_us']:.2f}  "
          f"p99.9 {c['p999_us']:.2f}  max {c['max_us']:.2f}")
    if args.realtime:
        w = stats["wake"]
        print(f"  wake latency [us]: p50 {w['p50_us']:.1f}  p99 {w['p99_us']:.1f}  "
              f"p99.9 {w['p999_us']:.1f}  max {w['max_us']:.1f}; overruns {stats['overruns']}")
    cmd = records["command"]
    print(f"  {'axis':<18}{'unit':>5}{'min':>10}{'max':>10}{'top speed':>11}{'limit':>9}")
    for j, axis in enumerate(config.axes):
        speed = np.max(np.abs(np.diff(cmd[:, j]))) / period if len(cmd) > 1 else 0.0
        print(f"  {axis.name:<18}{axis.unit:>5}{cmd[:, j].min():>10.4f}{cmd[:, j].max():>10.4f}"
              f"{speed:>11.4f}{axis.max_speed:>9.3g}")
    fault_lines, status = fault_summary(records, config, stats["overruns"])
    for line in fault_lines:
        print(line)
    if audio is not None:
        audio_latency = "-" if audio.latency is None else f"{audio.latency * 1e3:.0f} ms"
        print(f"  audio input {audio.name!r}: {audio.frames} frames, input latency {audio_latency}, "
              f"{audio.overflows} overflows"
              + (f"; LOST: {audio.lost_reason}" if audio.lost_reason is not None else ""))
        if audio.lost_reason is not None:
            status = 1
    verdict = verdict_line(share) if share is not None else None
    if verdict:
        print(verdict)
        status = 1
    return status or view.status
