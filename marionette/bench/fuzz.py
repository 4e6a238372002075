"""``marionette bench fuzz``: random and mutated frames through the C codec.

The loop is C (firmware_protocol/mar_fuzz.c, run without the GIL in a
child process, so that a crash or a hang is reported rather than suffered).
For each of N frames (default 10^6, fixed seed) it makes a random valid
message of any type, encodes it as a serial frame, and then

- 10 %: sends it unchanged: it must come out of the deframer exactly;
- 10 %: sends random garbage, then the frame twice: the second copy must
  come out exactly (the deframer resynchronises at the next 0x00);
- 15 %: flips 1..5 bits of the body before COBS: must never be accepted
  (CRC-32C has Hamming distance 6 up to 5243 bits; a frame is at most 2048);
- 65 %: mutates the wire bytes (bit flips, bursts, byte changes, insertions,
  deletions, truncation, overlong): whatever comes out is compared with the
  original message.

Corrupt frames that are well formed once their CRC is made right are the
CRC's trials; of those, CRC-32C should let through about trials * 2^-32,
and a 16-bit check (judged on the same frames by the low 16 CRC bits)
about trials * 2^-16, or fewer: bit-flip errors of low weight are caught
better than random ones. The verdict allows the binomial upper bound at
1e-6. Then N/4 messages are sent as CAN frames, mutated or random, through
the CAN receiver (no comparison: CAN has its own CRC; this checks that no
frame crashes it).

JSON (``--json``): one object with the C report's counters (frames, clean,
clean_lost, mutated, crc_trials, mutated_rejected, mutated_same,
accepted_corrupt, crc16_accepted, low_weight, low_weight_accepted,
garbage_runs, garbage_bytes, garbage_accepted, wire_bytes, can_frames,
can_messages) and seed, seconds, frames_per_s, wire_mb_per_s, crashed,
hung, expected_accepted, bound_accepted, expected_crc16, bound_crc16,
checks (name -> bool), passed, machine.
"""
from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile

from marionette.bench import STRICT_HELP, exit_status, verdict
from marionette.bench._machine import describe, machine_info
from marionette.cli.options import Number

DEFAULT_FRAMES = 1_000_000
SEED = 20261122
ALPHA = 1e-6                # the chance a correct codec fails a bound check
CRC_BITS = 32


def binomial_upper(n: int, p: float, alpha: float = ALPHA) -> int:
    """The smallest k with P(X > k) <= alpha for X ~ Binomial(n, p)."""
    if n <= 0 or p <= 0:
        return 0
    q = 1.0 - p
    log_pmf = n * math.log1p(-p)                    # P(X = 0)
    below = math.exp(log_pmf)
    k = 0
    while 1.0 - below > alpha and k < n:
        log_pmf += math.log((n - k) / (k + 1)) + math.log(p / q)
        k += 1
        below += math.exp(log_pmf)
    return k


def hang_limit(frames: int) -> float:
    """Seconds after which the run counts as hung: 100 us per frame, at least 60 s."""
    return max(60.0, frames * 1e-4)


def _worker(seed: int, frames: int) -> None:
    import time

    from marionette import protocol
    t0 = time.perf_counter()
    report = protocol.fuzz(seed, frames)
    report["seconds"] = time.perf_counter() - t0
    json.dump(report, sys.stdout)


def evaluate(report: dict) -> dict:
    """Adds the expectations, the checks and the verdict to a report."""
    trials = report["crc_trials"]
    report["expected_accepted"] = trials * 2.0 ** -CRC_BITS
    report["bound_accepted"] = binomial_upper(trials, 2.0 ** -CRC_BITS)
    report["expected_crc16"] = trials * 2.0 ** -16
    report["bound_crc16"] = binomial_upper(trials, 2.0 ** -16)
    garbage_bound = binomial_upper(report["garbage_bytes"], 2.0 ** -CRC_BITS)
    report["checks"] = {
        "no crash": not report["crashed"],
        "no hang": not report["hung"],
        "every frame made": report["frames"] == report["requested"],
        "clean frames all decoded": report["clean_lost"] == 0,
        "1..5-bit errors all refused": report["low_weight_accepted"] == 0,
        "corrupt accepted within the CRC-32C bound": report["accepted_corrupt"] <= report["bound_accepted"],
        "16-bit judgement within its bound": report["crc16_accepted"] <= report["bound_crc16"],
        "garbage accepted within the CRC-32C bound": report["garbage_accepted"] <= garbage_bound,
    }
    report["passed"] = all(report["checks"].values())
    return report


def collect(frames: int = DEFAULT_FRAMES, seed: int = SEED) -> dict:
    """The fuzz in a child process; its report, evaluated."""
    failed = {"crashed": False, "hung": False}
    try:
        child = subprocess.run([sys.executable, "-P", "-m", "marionette.bench.fuzz", "--worker",
                                "--frames", str(frames), "--seed", str(seed)],
                               capture_output=True, text=True, timeout=hang_limit(frames),
                               cwd=tempfile.gettempdir())   # the installed package, not a source tree
        if child.returncode != 0:
            failed["crashed"] = True
            failed["error"] = f"exit status {child.returncode}: {child.stderr.strip()[-2000:]}"
            report = {}
        else:
            report = json.loads(child.stdout)
    except subprocess.TimeoutExpired:
        failed["hung"] = True
        report = {}
    if not report:
        keys = ("frames", "clean", "clean_lost", "mutated", "crc_trials", "mutated_rejected",
                "mutated_same", "accepted_corrupt", "crc16_accepted", "low_weight",
                "low_weight_accepted", "garbage_runs", "garbage_bytes", "garbage_accepted",
                "wire_bytes", "can_frames", "can_messages")
        report = dict.fromkeys(keys, 0)
        report["seconds"] = float("nan")
    report.update(failed)
    report["requested"] = frames
    report["seed"] = seed
    seconds = report["seconds"]
    report["frames_per_s"] = report["frames"] / seconds if seconds > 0 else float("nan")
    report["wire_mb_per_s"] = report["wire_bytes"] / seconds / 1e6 if seconds > 0 else float("nan")
    report["machine"] = machine_info()
    return evaluate(report)


def format_report(r: dict) -> str:
    lines = [f"marionette bench fuzz: {r['requested']} random messages as serial frames, mutated, "
             f"through the C deframer and decoder (seed {r['seed']})",
             describe(r["machine"]), ""]
    if r["crashed"] or r["hung"]:
        lines.append(f"  the fuzz {'crashed' if r['crashed'] else 'hung'}: {r.get('error', '')}")
    lines += [
        f"  frames             {r['frames']}  (clean {r['clean']}, wire-mutated {r['mutated']}, "
        f"1..5-bit body errors {r['low_weight']}, garbage runs {r['garbage_runs']})",
        f"  speed              {r['frames_per_s']:,.0f} frames/s, {r['wire_mb_per_s']:.1f} MB/s "
        f"of wire bytes ({r['seconds']:.2f} s)",
        f"  crash / hang       {'yes' if r['crashed'] else 'none'} / {'yes' if r['hung'] else 'none'}",
        f"  clean frames lost  {r['clean_lost']}",
        f"  wire-mutated       {r['mutated_rejected']} gave nothing, {r['mutated_same']} gave the "
        f"original message, {r['accepted_corrupt']} gave another (accepted corrupt)",
        f"  CRC trials         {r['crc_trials']} corrupt frames well formed but for their CRC:",
        f"                     CRC-32C accepted {r['accepted_corrupt']} (expected "
        f"{r['expected_accepted']:.2g} at 2^-32, bound {r['bound_accepted']})",
        f"                     a 16-bit check would accept {r['crc16_accepted']} (expected "
        f"{r['expected_crc16']:.2f} at 2^-16 or fewer, bound {r['bound_crc16']})",
        f"  1..5-bit errors    {r['low_weight_accepted']} of {r['low_weight']} accepted "
        f"(Hamming distance 6)",
        f"  garbage            {r['garbage_bytes']} random bytes, {r['garbage_accepted']} messages",
        f"  CAN                {r['can_frames']} frames through the CAN receiver, "
        f"{r['can_messages']} messages",
        "",
        "checks:",
    ]
    for name, ok in r["checks"].items():
        lines.append(f"  {name:<45} {verdict(ok)}")
    return "\n".join(lines)


def register(sub) -> None:
    parser = sub.add_parser(
        "fuzz", help="random and mutated frames through the protocol decoder",
        description="Random and mutated frames through the C protocol decoder and deframer: "
                    "no crash, no hang, frames/s, corrupt frames accepted against the CRC's odds.")
    parser.add_argument("--frames", type=Number(int, 1), default=DEFAULT_FRAMES,
                        help=f"serial frames (default {DEFAULT_FRAMES}; CAN frames: about a quarter more)")
    parser.add_argument("--seed", type=Number(int, 0, 2**64 - 1), default=SEED,
                        help="seed of the fuzzer")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.add_argument("--strict", action="store_true", help=STRICT_HELP)
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)


def run(args) -> int:
    if args.worker:
        _worker(args.seed, args.frames)
        return 0
    report = collect(args.frames, args.seed)
    if args.json:
        json.dump(report, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        print(format_report(report))
    return exit_status(report["checks"].values(), args.strict)


def main(argv=None) -> int:
    """``python -m marionette.bench.fuzz``: as ``marionette bench fuzz``."""
    from marionette.cli import main as cli_main
    return cli_main(["bench", "fuzz", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
