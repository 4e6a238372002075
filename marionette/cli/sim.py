"""`marionette sim`: simulated servo nodes in their own process, behind a
real serial line (a pty) or CAN bus (slcan on a pty, or udp_multicast)."""
from __future__ import annotations

import json
import os
import stat
import sys

from marionette.config import load_config


def register(sub) -> None:
    p = sub.add_parser("sim", help="run simulated servo nodes behind a pty or CAN bus")
    p.add_argument("--config", help="figure TOML; default: the bundled Hoffmann 1996 figure")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--serial", action="store_true", help="serial protocol on a pty (default)")
    where.add_argument("--can", choices=("slcan", "udp_multicast"),
                       help="CAN: an slcan adapter emulated on a pty, or python-can's udp_multicast")
    p.add_argument("--channel", default="239.74.163.2",
                   help="udp_multicast group address (with --can udp_multicast)")
    p.add_argument("--seconds", type=float, help="stop after this long [s] (default: until 'quit')")
    p.add_argument("--watchdog-ticks", type=int, default=None,
                   help="ticks without a setpoint before a node stops (default: SPEC.md's)")
    p.add_argument("--drop", type=float, default=0.0, help="probability a received byte is lost")
    p.add_argument("--corrupt", type=float, default=0.0, help="probability a received byte is corrupted")
    p.add_argument("--delay", type=float, default=0.0, help="extra delay before a node acts [s]")
    p.add_argument("--noise", type=float, default=0.0, help="reported position noise [counts, std dev]")
    p.add_argument("--silent", type=int, nargs="*", default=[], help="nodes that do not answer")
    p.add_argument("--seed", type=int, default=0, help="seed of the fault injection")
    p.add_argument("--trace", help="write, at each SYNC, its arrival time (model time [s]; t0: "
                                   "CLOCK_MONOTONIC of model time 0), tick, the simulated "
                                   "positions [unit] and their model time (whole 1 ms steps) "
                                   "to this .npz")
    p.add_argument("--no-accel-clip", action="store_true",
                   help="drives that do not clip acceleration (only speed and position limits), "
                        "so that a command stream asking too much shows in the summary's "
                        "peak_accel [unit/s^2, from positions sampled once per tick]")
    p.add_argument("--music", help="a node measures this recording's loudness, played from the "
                                   "start of the run, and reports it in LOUDNESS messages")
    p.add_argument("--loudness-node", type=int, help="the node that does (default: the figure's last)")
    p.add_argument("--priority", type=int, default=0,
                   help="run at this SCHED_FIFO priority when permitted (0: normal), so the "
                        "simulated nodes keep time on a busy machine")
    p.set_defaults(run=run)


def control_stdin(stdin) -> bool:
    """Whether stdin may carry control lines: a pipe, or a terminal (read
    only while the simulator is in its foreground: server.run checks again
    before each read). Otherwise (`marionette sim --serial &` from a shell,
    /dev/null, a file) it is left alone, so a background run is never
    stopped for reading its terminal."""
    try:
        mode = os.fstat(stdin.fileno()).st_mode
    except (AttributeError, OSError, ValueError):
        return False
    return stat.S_ISFIFO(mode) or stat.S_ISSOCK(mode) or stdin.isatty()


def run(args) -> int:
    from marionette.sim.faults import Faults
    from marionette.sim.figure import SimFigure
    from marionette.sim.node import DEFAULT_WATCHDOG_TICKS
    from marionette.sim.server import SerialFrontEnd, SlcanFrontEnd, UdpFrontEnd, run as serve

    config = load_config(args.config)
    if args.priority:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.priority))
        except (OSError, ValueError) as exc:
            print(f"marionette sim: runs without SCHED_FIFO priority {args.priority}: {exc}",
                  file=sys.stderr)
    faults = Faults(drop_rate=args.drop, corrupt_rate=args.corrupt, delay=args.delay,
                    position_noise=args.noise, silent=set(args.silent), seed=args.seed)
    music = None
    if args.music:
        from marionette.music.feature import read_wav
        music = read_wav(args.music)
    node = args.loudness_node if args.loudness_node is not None else max(a.node for a in config.axes)
    figure = SimFigure(config, faults, args.watchdog_ticks or DEFAULT_WATCHDOG_TICKS,
                       trace=bool(args.trace), music=music, music_node=node,
                       clip_accel=not args.no_accel_clip)
    if args.can == "slcan":
        front = SlcanFrontEnd()
    elif args.can == "udp_multicast":
        front = UdpFrontEnd(args.channel)
    else:
        front = SerialFrontEnd()
    summary = serve(figure, front, faults, seconds=args.seconds, trace_path=args.trace,
                  control=sys.stdin if control_stdin(sys.stdin) else None)
    print(json.dumps({"summary": summary}), flush=True)
    return 0
