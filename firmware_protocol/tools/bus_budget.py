"""Bus budget of protocol version 1: bytes (or bits) per 20 ms tick, and the
share of the tick they take, for 16 axes on the links SPEC.md discusses.

    python firmware_protocol/tools/bus_budget.py

Frame sizes come from the codec itself (marionette.protocol). Per tick the
host sends SYNC and the setpoints; every node answers with STATUS (poll all;
"1 STATUS" rows: round-robin polling, the largest node's answer); one node
sends LOUDNESS with N_BANDS band levels; each node sends a HEARTBEAT every 50 ticks (averaged).
Serial: 10 bits per byte (8N1). CAN: classic frames with 11-bit identifiers,
47 + 8n bits plus the worst-case stuff bits floor((34 + 8n - 1) / 4), for n
data bytes (Davis et al., "Controller Area Network (CAN) schedulability
analysis: refuted, revisited and revised", 2007). SPEC.md quotes this
output; tests/test_protocol.py checks that it still does.
"""
from __future__ import annotations

import sys

from marionette import protocol as P
from marionette.music.bands import N_BANDS      # band levels in the LOUDNESS

TICK = 0.020                # [s]
HEARTBEAT_TICKS = 50        # a heartbeat per node every 50 ticks (1 s)

# (node, channels): the bundled figure (hoffmann1996.toml) and 16 one-axis nodes
LAYOUTS = {
    "Hoffmann figure: 16 axes on 5 nodes (9+1+1+1+4)": [(1, 9), (2, 1), (3, 1), (4, 1), (5, 4)],
    "16 one-axis nodes": [(n, 1) for n in range(1, 17)],
}
SERIAL = {"serial 115200 baud": 115200, "serial 1 Mbaud": 1_000_000}
CAN = {"CAN 500 kbit/s": 500_000, "CAN 1 Mbit/s": 1_000_000}


def can_bits(n: int) -> int:
    """Worst-case length of a classic CAN frame with an 11-bit id and n data bytes [bits]."""
    return 47 + 8 * n + (34 + 8 * n - 1) // 4


def traffic(layout):
    """Serial bytes and CAN frames (as data lengths) per tick, each way."""
    tick = 123456
    entries = [(node, ch, 12000) for node, k in layout for ch in range(k)]
    statuses = [P.Status(node, tick, positions=[12000] * k) for node, k in layout]
    out_serial = len(P.encode_serial(P.Sync(tick))) + len(P.encode_serial(P.Setpoints(tick, entries)))
    status_serial = [len(P.encode_serial(s)) for s in statuses]
    loudness = P.Loudness(6, tick, 0.5, [0.1] * N_BANDS)
    loud_serial = len(P.encode_serial(loudness))
    beat_serial = len(P.encode_serial(P.Heartbeat(1, P.STATE_OPERATIONAL))) * len(layout) / HEARTBEAT_TICKS
    out_can = [len(d) for m in (P.Sync(tick), P.Setpoints(tick, entries)) for _, d in P.encode_can(m)]
    status_can = [[len(d) for _, d in P.encode_can(s)] for s in statuses]
    loud_can = [len(d) for _, d in P.encode_can(loudness)]
    beat_bits = can_bits(1) * len(layout) / HEARTBEAT_TICKS
    return dict(out_serial=out_serial, status_serial=status_serial, loud_serial=loud_serial,
                beat_serial=beat_serial, out_can=out_can, status_can=status_can, loud_can=loud_can,
                beat_bits=beat_bits)


def rows(layout) -> list[tuple[str, str, str, str]]:
    """(link, host to nodes, nodes to host, total) per link, as text."""
    t = traffic(layout)
    out = []
    for name, baud in SERIAL.items():
        per_bit = 10 / baud / TICK                          # share of a tick one byte takes / 10
        down = t["out_serial"]
        up_all = sum(t["status_serial"]) + t["loud_serial"] + t["beat_serial"]
        up_one = max(t["status_serial"]) + t["loud_serial"] + t["beat_serial"]
        for label, up in (("all STATUS", up_all), ("1 STATUS", up_one)):
            out.append((f"{name}, {label}", f"{down} B, {down * per_bit:.1%}",
                        f"{up:.0f} B, {up * per_bit:.1%}", f"{(down + up) * per_bit:.1%}"))
    down_bits = sum(can_bits(n) for n in t["out_can"])
    up_bits = sum(can_bits(n) for s in t["status_can"] for n in s) + sum(
        can_bits(n) for n in t["loud_can"]) + t["beat_bits"]
    n_down = len(t["out_can"])
    n_up = sum(map(len, t["status_can"])) + len(t["loud_can"])
    for name, rate in CAN.items():
        share = 1 / rate / TICK
        out.append((name, f"{n_down} frames, {down_bits} bit, {down_bits * share:.1%}",
                    f"{n_up} frames, {up_bits:.0f} bit, {up_bits * share:.1%}",
                    f"{(down_bits + up_bits) * share:.1%}"))
    return out


def table() -> str:
    lines = []
    for title, layout in LAYOUTS.items():
        lines += [f"{title}, 50 Hz:", "",
                  "| link | host to nodes per tick | nodes to host per tick | total (shared medium) |",
                  "| --- | --- | --- | --- |"]
        lines += [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rows(layout)]
        lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.stdout.write(table())
