"""`marionette sim`: simulated servo nodes in their own process, behind a
real serial line (a pty) or CAN bus (slcan on a pty, or udp_multicast)."""
from __future__ import annotations

import json
import os
import stat
import sys

from marionette.cli.options import CONFIG_HELP, PRIORITY, SEED, Number, input_file, output_file
from marionette.config import load_config
from marionette.errors import MarionetteError

PROBABILITY = Number(float, 0.0, 1.0)


def register(sub) -> None:
    p = sub.add_parser("sim", help="run simulated servo nodes behind a pty or CAN bus",
                       description="Simulated servo nodes of a figure in this process, behind a "
                       "serial line (a pty) or a CAN bus (slcan on a pty, or udp_multicast), with "
                       "injected faults. First prints one JSON line that says where to connect; "
                       "at the end ('quit' on stdin, --seconds, SIGTERM) a JSON summary. Lines on "
                       "stdin change the faults while it runs: 'silence N', 'resume N', "
                       "'drop R', 'corrupt R', 'delay S', 'noise C', 'quit'.")
    p.add_argument("--config", type=input_file, help=CONFIG_HELP)
    where = p.add_mutually_exclusive_group()
    where.add_argument("--serial", action="store_true", help="serial protocol on a pty (default)")
    where.add_argument("--can", choices=("slcan", "udp_multicast"),
                       help="CAN: an slcan adapter emulated on a pty, or python-can's udp_multicast")
    p.add_argument("--channel", default="239.74.163.2",
                   help="udp_multicast group address (with --can udp_multicast)")
    p.add_argument("--seconds", type=Number(float, 0.0, above=True),
                   help="stop after this long [s] (default: until 'quit')")
    p.add_argument("--watchdog-ticks", type=Number(int, 1, 65535), default=None,
                   help="ticks without a setpoint before a node stops (default: SPEC.md's)")
    p.add_argument("--drop", type=PROBABILITY, default=0.0,
                   help=f"probability a received byte is lost, {PROBABILITY.range}")
    p.add_argument("--corrupt", type=PROBABILITY, default=0.0,
                   help=f"probability a received byte is corrupted, {PROBABILITY.range}")
    p.add_argument("--delay", type=Number(float, 0.0, 10.0), default=0.0,
                   help="extra delay before a node acts [s]")
    p.add_argument("--noise", type=Number(float, 0.0), default=0.0,
                   help="reported position noise [counts, std dev]")
    p.add_argument("--silent", type=Number(int, 0, 255), nargs="*", default=[],
                   help="nodes that do not answer (nodes of the figure)")
    p.add_argument("--seed", type=SEED, default=0, help="seed of the fault injection")
    p.add_argument("--trace", type=output_file,
                   help="write, at each SYNC, its arrival time (model time [s]; t0: "
                        "CLOCK_MONOTONIC of model time 0), tick, the simulated "
                        "positions [unit] and their model time (whole 1 ms steps) "
                        "to this .npz")
    p.add_argument("--no-accel-clip", action="store_true",
                   help="drives that do not clip acceleration (only speed and position limits), "
                        "so that a command stream asking too much shows in the summary's "
                        "peak_accel [unit/s^2, from positions sampled once per tick]")
    p.add_argument("--music", type=input_file,
                   help="a node measures this recording's loudness and band loudness, played "
                        "from the start of the run, and reports them in LOUDNESS messages")
    p.add_argument("--loudness-only", action="store_true",
                   help="with --music: the node sends the loudness alone, without bands (a "
                        "one-band node, as before bands were in the protocol)")
    p.add_argument("--loudness-node", type=Number(int, 0, 255),
                   help="the node that does (default: the figure's last)")
    p.add_argument("--priority", type=PRIORITY, default=0,
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
    nodes = sorted({a.node for a in config.axes})
    for option, node in [("--silent", n) for n in args.silent] + [("--loudness-node", args.loudness_node)]:
        if node is not None and node not in nodes:
            raise MarionetteError(f"{option} {node}: {config.source} has no node {node} "
                                  f"(its nodes: {', '.join(map(str, nodes))})")
    if args.loudness_only and not args.music:
        raise MarionetteError("--loudness-only: there is no --music for a node to measure")
    if args.priority:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.priority))
        except (OSError, ValueError) as exc:
            print(f"marionette sim: runs without SCHED_FIFO priority {args.priority}: {exc}",
                  file=sys.stderr)
    faults = Faults(drop_rate=args.drop, corrupt_rate=args.corrupt, delay=args.delay,
                    position_noise=args.noise, silent=set(args.silent), seed=args.seed,
                    nodes=frozenset(nodes))
    music = None
    if args.music:
        from marionette.music.feature import AudioError, LoudnessMeter, read_wav
        music = read_wav(args.music)
        try:
            LoudnessMeter(music[1])        # a rate the node can measure
        except AudioError as exc:
            raise AudioError(f"{args.music}: {exc}") from None
    node = args.loudness_node if args.loudness_node is not None else nodes[-1]
    figure = SimFigure(config, faults, args.watchdog_ticks or DEFAULT_WATCHDOG_TICKS,
                       trace=bool(args.trace), music=music, music_node=node,
                       clip_accel=not args.no_accel_clip, music_bands=not args.loudness_only)
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
