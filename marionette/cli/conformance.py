"""``marionette conformance``: check a servo node (or the simulator) against
firmware_protocol/SPEC.md over a serial line or a CAN bus."""
from __future__ import annotations

import contextlib
import json
import sys

from marionette.cli.options import Number


def register(sub) -> None:
    p = sub.add_parser("conformance", help="check a servo node against firmware_protocol/SPEC.md")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--serial", metavar="URL[@BAUD]",
                       help="a serial port or pyserial URL, e.g. /dev/ttyUSB0@1000000 (default 1000000 baud)")
    where.add_argument("--can", metavar="INTERFACE:CHANNEL[@BITRATE]",
                       help="a python-can bus, e.g. socketcan:can0 or slcan:/dev/ttyACM0@500000 "
                            "(default 500000 bit/s)")
    p.add_argument("--node", type=Number(int, 1, 254), default=1,
                   help="the node's address (default 1; on CAN at most 127)")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(run=run)


def run(args) -> int:
    from marionette.conformance import LinkError, format_report, open_link, run_checks
    top = 127 if args.can else 254
    if not 1 <= args.node <= top:
        print(f"marionette conformance: --node {args.node}: a node address is 1..{top}"
              f"{' on CAN' if args.can else ''}", file=sys.stderr)
        return 2
    try:
        link = open_link("can" if args.can else "serial", args.can or args.serial)
    except LinkError as exc:
        print(f"marionette conformance: {exc}", file=sys.stderr)
        return 2
    try:
        report = run_checks(link, args.node)
    except OSError as exc:              # the port went away (serial.SerialException, CAN devices)
        print(f"marionette conformance: the link failed: {exc}", file=sys.stderr)
        return 2
    finally:
        with contextlib.suppress(OSError):
            link.close()
    print(json.dumps(report) if args.json else format_report(report), flush=True)
    return 1 if report["failed"] else 0
