"""Writes firmware_protocol/marionette.dbc: the CAN mapping of protocol
version 1 (SPEC.md, "CAN mapping") as a DBC database, for CAN analysers and
cantools.

    python firmware_protocol/tools/make_dbc.py [--nodes N] [-o marionette.dbc]

A DBC names every identifier, so the file lists nodes 1..N (16 by default;
the mapping allows 1..127). tests/test_protocol.py checks that the committed
file is what this writes, and that cantools decodes and encodes the codec's
frames to the same values.
"""
from __future__ import annotations

import argparse
import sys

HOST = "HOST"
ANY = "Vector__XXX"
INT20 = (-524287, 524287)   # counts; -524288 is NONE, outside the range
NONE = -524288
BANDS = 7                   # band codes in a LOUDNESS bands frame, at most
U32 = 4294967295
STATES = {0: "BOOT", 4: "STOPPED", 5: "OPERATIONAL", 127: "PRE_OPERATIONAL"}
PARAMS = {1: "BEGIN", 2: "WATCHDOG", 16: "MIN", 17: "MAX", 18: "SPEED", 19: "ACCEL", 127: "APPLY"}
REASONS = {0: "ACCEPTED", 1: "BAD_VERSION", 2: "BAD_TYPE", 3: "BAD_LENGTH", 4: "BAD_VALUE",
           5: "BAD_CHANNEL", 6: "BAD_CONFIG", 7: "ESTOP_LATCHED", 8: "STALE",
           9: "CONFIG_INCOMPLETE", 4096: "DRIVE_FAULT"}


def signal(name, start, length, signed=False, unit="", mux="", lo=None, hi=None):
    full = (-(1 << (length - 1)), (1 << (length - 1)) - 1) if signed else (0, (1 << length) - 1)
    lo = full[0] if lo is None else lo
    hi = full[1] if hi is None else hi
    mux = f" {mux}" if mux else ""
    return (f' SG_ {name}{mux} : {start}|{length}@1{"-" if signed else "+"} (1,0) [{lo}|{hi}] '
            f'"{unit}" {ANY}')


def message(can_id, name, dlc, sender, signals):
    return [f"BO_ {can_id} {name}: {dlc} {sender}", *signals, ""]


def pdo(first):
    """Counter, then three int20 channels: a setpoint or a positions PDO."""
    out = [signal("counter", 0, 4)]
    for k in range(3):
        out.append(signal(f"ch{first + k}", 4 + 20 * k, 20, True, "counts", lo=INT20[0], hi=INT20[1]))
    return out


def build(n_nodes: int) -> str:
    nodes = [f"NODE{n}" for n in range(1, n_nodes + 1)]
    lines = ['VERSION "marionette servo protocol 1"', "", "NS_ :", "    CM_", "    VAL_",
             "    SIG_VALTYPE_", "", "BS_:", "", "BU_: " + " ".join([HOST] + nodes), ""]
    comments, values, floats = [], [], []
    lines += message(0x001, "ESTOP", 1, HOST, [signal("node", 0, 8, lo=1, hi=255)])
    comments.append(f'CM_ BO_ {0x001} "Latch the e-stop of one node, or of every node (255)";')
    lines += message(0x002, "ESTOP_RELEASE", 1, HOST, [signal("node", 0, 8, lo=1, hi=255)])
    comments.append(f'CM_ BO_ {0x002} "Release the e-stop latch of one node, or of every node (255)";')
    lines += message(0x080, "SYNC", 1, HOST, [signal("counter", 0, 8)])
    comments.append(f'CM_ BO_ {0x080} "A tick begins: tick mod 256";')
    for n in range(1, n_nodes + 1):
        me = f"NODE{n}"
        lines += message(0x080 + n, f"NACK_N{n}", 8, me, [
            signal("reason", 0, 16), signal("flags", 16, 8, hi=31), signal("ref_type", 24, 8),
            signal("ref_seq", 32, 32)])
        values.append((0x080 + n, "reason", REASONS))
        lines += message(0x180 + n, f"STATUS_N{n}", 8, me, [
            signal("counter", 0, 8), signal("flag_limit", 8, 1), signal("flag_fault", 9, 1),
            signal("flag_watchdog", 10, 1), signal("flag_following", 11, 1), signal("flag_estop", 12, 1),
            signal("reserved", 13, 3, hi=0), signal("state", 16, 8, hi=127),
            signal("channels", 24, 8, hi=9), signal("rejected", 32, 16),
            signal("seq_gaps", 48, 16)])
        values.append((0x180 + n, "state", STATES))
        for k, letter in enumerate("ABC"):
            sp, pos = 0x200 + 0x100 * k + n, 0x280 + 0x100 * k + n
            lines += message(sp, f"SETPOINT_{letter}_N{n}", 8, HOST, pdo(3 * k))
            lines += message(pos, f"POSITION_{letter}_N{n}", 8, me, pdo(3 * k))
            for can_id in (sp, pos):
                for c in range(3 * k, 3 * k + 3):
                    values.append((can_id, f"ch{c}", {NONE: "NONE"}))
        lines += message(0x600 + n, f"CONFIG_N{n}", 8, HOST, [
            signal("param", 0, 8, mux="M"), signal("reserved", 16, 16, hi=0),
            signal("begin_channel", 8, 8, mux="m1", lo=255, hi=255),
            signal("tick_period_us", 32, 32, unit="us", mux="m1", lo=1, hi=U32),
            signal("watchdog_channel", 8, 8, mux="m2", lo=255, hi=255),
            signal("watchdog_ticks", 32, 32, unit="ticks", mux="m2", lo=1, hi=65535),
            signal("min_channel", 8, 8, mux="m16", hi=8),
            signal("min_counts", 32, 32, True, "counts", mux="m16"),
            signal("max_channel", 8, 8, mux="m17", hi=8),
            signal("max_counts", 32, 32, True, "counts", mux="m17"),
            signal("speed_channel", 8, 8, mux="m18", hi=8),
            signal("max_speed", 32, 32, unit="counts/s", mux="m18", lo=1, hi=U32),
            signal("accel_channel", 8, 8, mux="m19", hi=8),
            signal("max_accel", 32, 32, unit="counts/s^2", mux="m19", lo=1, hi=U32),
            signal("channels", 8, 8, mux="m127", hi=9),
            signal("seq", 32, 32, mux="m127")])
        values.append((0x600 + n, "param", PARAMS))
        lines += message(0x580 + n, f"LOUDNESS_BANDS_N{n}", 8, me, [
            signal("counter", 0, 4), signal("bands", 4, 4, lo=1, hi=BANDS),
            *(signal(f"band{k}", 8 + 8 * k, 8) for k in range(BANDS))])
        for k in range(BANDS):
            values.append((0x580 + n, f"band{k}", {255: "SILENT"}))
        lines += message(0x680 + n, f"LOUDNESS_N{n}", 8, me, [
            signal("frame", 0, 32), signal("loudness", 32, 32, True, lo=0, hi="3.4028234663852886e+38")])
        floats.append((0x680 + n, "loudness"))
        lines += message(0x700 + n, f"HEARTBEAT_N{n}", 1, me, [signal("state", 0, 8, hi=127)])
        values.append((0x700 + n, "state", STATES))
        comments += [
            f'CM_ BO_ {0x080 + n} "NACK of node {n} (CANopen EMCY place): reason 0 acknowledges a CONFIG";',
            f'CM_ BO_ {0x180 + n} "STATUS header of node {n}, answering SYNC counter; positions follow";',
            *(f'CM_ BO_ {0x200 + 0x100 * k + n} "Setpoints of node {n}, channels {3 * k}..{3 * k + 2}; '
              f'counter = tick mod 16; NONE: no value";' for k in range(3)),
            *(f'CM_ BO_ {0x280 + 0x100 * k + n} "Actual positions of node {n}, channels '
              f'{3 * k}..{3 * k + 2}; NONE: no such channel";' for k in range(3)),
            f'CM_ BO_ {0x600 + n} "CONFIG of node {n}, one parameter per frame from BEGIN (1) to APPLY (127)";',
            f'CM_ BO_ {0x580 + n} "Band levels of node {n}\'s next LOUDNESS (counter = its frame mod 16): '
            f'code c is +6 dB - 0.5 dB * c re full scale, 255 silent; band codes past the count are reserved (0)";',
            f'CM_ BO_ {0x680 + n} "Loudness of one 20 ms audio frame measured by node {n}";',
            f'CM_ BO_ {0x700 + n} "Heartbeat of node {n}: its state";',
            *(f'CM_ SG_ {can_id} reserved "Reserved: sent as 0; a frame where it is not 0 is refused";'
              for can_id in (0x180 + n, 0x600 + n)),
        ]
    lines += comments
    lines.append("")
    for can_id, name, table in values:
        choices = " ".join(f'{k} "{v}"' for k, v in table.items())
        lines.append(f"VAL_ {can_id} {name} {choices} ;")
    lines.append("")
    for can_id, name in floats:
        lines.append(f"SIG_VALTYPE_ {can_id} {name} : 1;")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--nodes", type=int, default=16, help="nodes 1..N (at most 127)")
    parser.add_argument("-o", "--output", help="file to write (default: stdout)")
    args = parser.parse_args(argv)
    if not 1 <= args.nodes <= 127:
        parser.error("--nodes must be 1..127")
    text = build(args.nodes)
    if args.output:
        with open(args.output, "w") as f:
            f.write(text)
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
