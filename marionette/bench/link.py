"""``marionette bench link``: how long a tick's frames take to reach a
servo node, and how fast the codec is.

Latency: the engine runs the bundled figure in real time against
`marionette sim` in its own process, over a pty (serial protocol) and over
CAN (python-can's slcan interface on a pty). The simulator notes when it
has decoded each tick's SYNC (CLOCK_MONOTONIC); the flight record has the
tick's scheduled time on the same clock. The difference is the latency
from the tick to a decoded frame: wake-up, encoding, the link and the
simulator's own wake-up and decoding. Baseline, same run: the tick
thread's wake latency (the part of it the link cannot improve).

Codec rates: one tick of the figure (SYNC + SETPOINT frames) encoded,
and a stream of such ticks deframed and decoded, through the binding;
baseline: zlib.crc32 over the same bytes (one bare checksum pass).

JSON (``--json``): {"links": [{link, ticks, received, p50_us, p99_us,
max_us, wake_p50_us, wake_p99_us}], "codec": {encode_ticks_per_s,
decode_frames_per_s, decode_mb_per_s, crc32_mb_per_s, decode_vs_crc32},
"machine": ...}.
"""
from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
import warnings
import zlib
from pathlib import Path

import numpy as np

from marionette import protocol
from marionette.bench._machine import describe, machine_info
from marionette.cli.options import Number
from marionette.config import load_config
from marionette.demo import DEMO_SHOW
from marionette.engine import Engine
from marionette.errors import MarionetteError
from marionette.show import load_show

PRIORITY = 40           # SCHED_FIFO of the engine, when permitted
SIM_PRIORITY = 30       # and of the simulator


def _start_sim(args: list[str]) -> tuple[subprocess.Popen, dict]:
    proc = subprocess.Popen([sys.executable, "-P", "-m", "marionette.cli", "sim", *args],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=tempfile.gettempdir())
    ready = json.loads(proc.stdout.readline() or "{}")
    if not ready.get("ready"):
        proc.kill()
        raise MarionetteError(f"simulator did not start: {proc.stderr.read()}")
    return proc, ready


def link_latency(kind: str, seconds: float) -> dict:
    """Tick -> decoded SYNC in the simulator over 'serial' (pty) or 'can' (slcan on a pty)."""
    from marionette.transport.can_link import CanLink
    from marionette.transport.serial_link import SerialLink
    config = load_config(None)
    show = load_show(DEMO_SHOW, config)
    ticks = int(round(seconds / config.tick_period))
    with tempfile.TemporaryDirectory() as tmp:
        trace = Path(tmp) / "trace.npz"
        sim_args = ["--serial"] if kind == "serial" else ["--can", "slcan"]
        proc, ready = _start_sim(sim_args + ["--priority", str(SIM_PRIORITY), "--trace", str(trace)])
        try:
            link = (SerialLink(ready["serial"]) if kind == "serial" else
                    CanLink(interface="slcan", channel=ready["channel"], bitrate=1000000))
            with Engine(config, show, output=link, record=True) as engine:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)
                    engine.start(priority=PRIORITY, max_ticks=ticks)
                engine.wait(seconds + 10)
                engine.stop()
                records = engine.records()
                stats = engine.stats()
            link.close()
            proc.communicate("quit\n", timeout=20)
        finally:
            if proc.poll() is None:
                proc.kill()
        t = np.load(trace)
        arrival = t["t0"] + t["time"]                               # [s] CLOCK_MONOTONIC
        scheduled = records["time_ns"][t["tick"]] * 1e-9            # [s]
        lat = (arrival - scheduled) * 1e6                           # [us]
    return {"link": "pty, serial protocol" if kind == "serial" else "slcan on a pty, CAN mapping",
            "ticks": ticks, "received": int(len(lat)),
            "p50_us": float(np.percentile(lat, 50)), "p99_us": float(np.percentile(lat, 99)),
            "max_us": float(lat.max()),
            "wake_p50_us": stats["wake"]["p50_us"], "wake_p99_us": stats["wake"]["p99_us"]}


def codec_rates(seconds: float = 0.5) -> dict:
    """Encode and decode rates of the figure's tick through the binding."""
    config = load_config(None)
    entries = [(a.node, a.channel, int(a.offset + a.scale * a.home)) for a in config.axes]
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        for k in range(n, n + 200):
            protocol.encode_serial(protocol.Sync(k))
            protocol.encode_serial(protocol.Setpoints(k, entries))
        n += 200
    encode_rate = n / (time.perf_counter() - t0)
    stream = b"".join(protocol.encode_serial(protocol.Sync(k))
                      + protocol.encode_serial(protocol.Setpoints(k, entries)) for k in range(2000))
    frames = 0
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        frames += len(protocol.Deframer().feed(stream))
    elapsed = time.perf_counter() - t0
    decode_mb = frames / 4000 * len(stream) / elapsed / 1e6
    done, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        zlib.crc32(stream)
        done += len(stream)
    crc_mb = done / (time.perf_counter() - t0) / 1e6
    return {"encode_ticks_per_s": encode_rate, "decode_frames_per_s": frames / elapsed,
            "decode_mb_per_s": decode_mb, "crc32_mb_per_s": crc_mb,
            "decode_vs_crc32": decode_mb / crc_mb}


def format_report(r: dict) -> str:
    lines = [f"{'link':<30}{'ticks':>7}{'got':>6}{'p50 us':>9}{'p99 us':>9}{'max us':>9}"
             f"{'wake p50':>10}{'wake p99':>10}"]
    for x in r["links"]:
        lines.append(f"{x['link']:<30}{x['ticks']:>7}{x['received']:>6}{x['p50_us']:>9.0f}"
                     f"{x['p99_us']:>9.0f}{x['max_us']:>9.0f}{x['wake_p50_us']:>10.0f}"
                     f"{x['wake_p99_us']:>10.0f}")
    c = r["codec"]
    lines.append(f"codec, through the binding: encode {c['encode_ticks_per_s']:,.0f} ticks/s "
                 f"(SYNC + SETPOINT of 16 axes); deframe+decode {c['decode_frames_per_s']:,.0f} "
                 f"frames/s = {c['decode_mb_per_s']:.1f} MB/s, {c['decode_vs_crc32']:.3f} x "
                 f"zlib.crc32 over the same bytes ({c['crc32_mb_per_s']:.0f} MB/s)")
    lines.append(describe(r["machine"]))
    return "\n".join(lines)


def register(sub) -> None:
    parser = sub.add_parser(
        "link", help="latency from the tick to a decoded frame in the simulator; codec rates",
        description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=Number(float, 0.0, above=True), default=5.0,
                        help="real-time run per link [s]")
    parser.add_argument("--json", action="store_true", help="print JSON instead of the table")


def run(args) -> int:
    report = {"links": [link_latency(kind, args.seconds) for kind in ("serial", "can")],
              "codec": codec_rates(), "machine": machine_info()}
    print(json.dumps(report, indent=2) if args.json else format_report(report))
    return 0


def main(argv=None) -> int:
    """``python -m marionette.bench.link``: as ``marionette bench link``."""
    from marionette.cli import main as cli_main
    return cli_main(["bench", "link", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
