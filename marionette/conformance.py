"""A conformance tester for servo nodes: drives one node over a serial line
or a CAN bus as the host would, provokes every behaviour
firmware_protocol/SPEC.md defines that a host can provoke, and checks the
answers. Each check cites its SPEC.md section.

The node must be fresh (just started: its first HEARTBEAT is BOOT) and
alone with the tester on the link. The tester configures it (CONFIG: limits
of +-LIMIT_SPAN counts around where each channel stands, watchdog
WATCHDOG_TICKS) and moves channel 0 by a few hundred counts.

    report = run_checks(open_link("serial", "/dev/ttyUSB0@1000000"), node=1)
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass

from marionette import protocol as P
from marionette.errors import MarionetteError

TICK = 0.02                 # the tester's tick period [s], also sent in its CONFIG
WATCHDOG_TICKS = 5          # the watchdog the tester configures [ticks]
LIMIT_SPAN = 2000           # limits configured around each channel's start position [counts]
STEP = 300                  # the move of channel 0 [counts]
FIRST_ANSWER_TICKS = 2      # the first STATUS must come within this many ticks of the first SYNC
START_TICKS = 50            # how long the tester waits for the first STATUS [ticks]
WAY = 0.005                 # a frame's way to the node, at most [s]
WATCHDOG_SLACK = 2          # the node may notice its watchdog this much late [ticks]
LATE_TICKS = 10             # how long a tick waits for its STATUS, once the node has answered [ticks]
LOUDNESS_TICKS = 25         # ticks whose LOUDNESS answers are checked, if the node sends any
WRAP_FROM = 2**32 - 3       # the tick the seq wrap check restarts at
SERIAL_BAUD = 1_000_000     # default [baud]
CAN_BITRATE = 500_000       # default [bit/s]


class LinkError(MarionetteError):
    """The link could not be opened: a message for the user."""


# -- links ------------------------------------------------------------------

class SerialLink:
    protocol = "serial"

    def __init__(self, address: str):
        url, _, baud = address.rpartition("@") if "@" in address else (address, "", "")
        try:
            self.baud = int(baud) if baud else SERIAL_BAUD
        except ValueError:
            raise LinkError(f"--serial {address!r}: baud rate {baud!r} is not a whole number") from None
        self.url = url
        self.port = None
        self.open()

    def open(self) -> None:
        import serial
        try:
            self.port = serial.serial_for_url(self.url, baudrate=self.baud, timeout=0)
        except (serial.SerialException, ValueError) as exc:
            raise LinkError(f"--serial {self.url}: {exc}") from None
        self.deframer = P.Deframer()

    def close(self) -> None:
        self.port.close()

    def send(self, message) -> None:
        self.port.write(P.encode_serial(message))

    def send_bytes(self, data: bytes) -> None:
        self.port.write(data)

    def receive(self, timeout: float) -> list:
        self.port.timeout = max(timeout, 0.0)
        data = self.port.read(max(1, self.port.in_waiting))
        if data and self.port.in_waiting:
            data += self.port.read(self.port.in_waiting)
        return self.deframer.feed(data) if data else []

    def refused(self) -> int:
        """Frames from the node that the decoder refused so far."""
        return self.deframer.rejected


class CanLink:
    protocol = "can"

    def __init__(self, address: str):
        interface, sep, rest = address.partition(":")
        if not sep or not interface or not rest:
            raise LinkError(f"--can {address!r}: expected INTERFACE:CHANNEL[@BITRATE], "
                            f"e.g. socketcan:can0 or slcan:/dev/ttyACM0@500000")
        channel, _, rate = rest.rpartition("@") if "@" in rest else (rest, "", "")
        try:
            self.bitrate = int(rate) if rate else CAN_BITRATE
        except ValueError:
            raise LinkError(f"--can {address!r}: bit rate {rate!r} is not a whole number") from None
        self.interface, self.channel = interface, channel
        self.bus = None
        self.open()

    def open(self) -> None:
        import can
        kwargs = {"interface": self.interface, "channel": self.channel, "bitrate": self.bitrate}
        if self.interface == "slcan":
            kwargs["sleep_after_open"] = 0.0
        if self.interface == "udp_multicast":
            kwargs.pop("bitrate")
        try:
            self.bus = can.Bus(**kwargs)
        except (can.CanError, OSError, ValueError, ImportError) as exc:
            raise LinkError(f"--can {self.interface}:{self.channel}: {exc}") from None
        self.decoder = P.CanDecoder()       # fed our own SYNCs too: it unwraps STATUS ticks

    def close(self) -> None:
        import can
        try:
            self.bus.shutdown()
        except can.CanError as exc:
            raise OSError(f"CAN {self.interface}:{self.channel}: {exc}") from None

    def send(self, message) -> None:
        for can_id, data in P.encode_can(message):
            self.send_frame(can_id, data)

    def send_frame(self, can_id: int, data: bytes) -> None:
        import can
        if can_id == P.CAN_SYNC:
            self.decoder.feed(can_id, data)
        try:
            self.bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
        except can.CanError as exc:
            raise OSError(f"CAN {self.interface}:{self.channel}: {exc}") from None

    def receive(self, timeout: float) -> list:
        import can
        try:
            msg = self.bus.recv(max(timeout, 0.0))
        except can.CanError as exc:
            raise OSError(f"CAN {self.interface}:{self.channel}: {exc}") from None
        if msg is None or msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id:
            return []
        return self.decoder.feed(msg.arbitration_id, bytes(msg.data))

    def refused(self) -> int:
        """Frames from the node that the decoder refused so far."""
        return self.decoder.rejected


def open_link(kind: str, address: str):
    return SerialLink(address) if kind == "serial" else CanLink(address)


def sealed(body: bytes) -> bytes:
    """A serial frame of these header and payload bytes with a good CRC."""
    return P.cobs_encode(body + P.crc32c(body).to_bytes(4, "little")) + b"\0"


# -- the checks ---------------------------------------------------------------

@dataclass
class Check:
    section: str                # SPEC.md section
    name: str
    ok: bool
    detail: str = ""


class Tester:
    """Runs ticks against one node and records checks."""

    def __init__(self, link, node: int):
        self.link, self.node = link, node
        self.can = link.protocol == "can"
        self.tick = 0                   # the next SYNC's tick
        self.seq = 100                  # the tester's command counter (ESTOP, CONFIG)
        self.checks: list[Check] = []
        self.targets: list[int] | None = None   # setpoints sent each tick, or None
        self.start: list[int] = []      # positions at the start [counts]
        self.channels = 0               # the node's channels (its STATUS's positions)
        self.answered = False           # the node has answered a SYNC: later ticks wait for theirs
        self.sent_at: dict[int, float] = {}     # tick (mod 256 on CAN) -> when its SYNC went [s]
        self.figures: dict = {}

    # the wire ----------------------------------------------------------------
    def check(self, section: str, name: str, ok: bool, detail: str = "") -> bool:
        self.checks.append(Check(section, name, bool(ok), "" if ok else detail))
        return bool(ok)

    def mine(self, messages) -> list:
        return [m for m in messages if isinstance(m, (P.Status, P.Heartbeat, P.Nack, P.Loudness))
                and m.node == self.node]

    def collect(self, until: float, status_of: int | None = None) -> list:
        """What the node sends until `until` (monotonic [s]); with status_of,
        on until the STATUS of that tick came too (at most LATE_TICKS more),
        so that a node or simulator answering late is judged by its answers,
        not by when they came."""
        out, late, status_late = [], until + LATE_TICKS * TICK, False
        while True:
            now = time.monotonic()
            waiting = status_of is not None and not any(
                isinstance(m, P.Status) and self.same_tick(m.tick, status_of) for m in out)
            if now >= (late if waiting else until):
                break
            out += self.mine(self.link.receive((late if waiting else until) - now))
            status_late = waiting and time.monotonic() > until
        if status_late:
            # the STATUS came late: the rest of its answer (a LOUDNESS after
            # it, a frame of its own on CAN) is on its way behind it, and
            # belongs to this tick, not to the next
            rest = now + WAY
            while (now := time.monotonic()) < rest:
                out += self.mine(self.link.receive(rest - now))
        return out

    def sync(self, setpoints: bool = True, poll: int = P.BROADCAST, extra=None) -> list:
        """One tick: SYNC, this node's setpoints (when streaming), then extra();
        returns what the node sent until the next tick (and its STATUS of
        this tick, when polled)."""
        t0 = time.monotonic()
        k = self.tick
        self.sent_at[self.wrap(k)] = t0
        self.link.send(P.Sync(k, poll) if not self.can else P.Sync(k))
        if setpoints and self.targets is not None:
            self.link.send(P.Setpoints(k, [(self.node, c, v) for c, v in enumerate(self.targets)]))
        if extra is not None:
            extra()
        self.tick = (k + 1) % 2**32
        answered = self.answered and poll in (P.BROADCAST, self.node)
        return self.collect(t0 + TICK, k if answered else None)

    def ticks(self, n: int, **kw) -> list[list]:
        return [self.sync(**kw) for _ in range(n)]

    def command_seq(self) -> int:
        self.seq += 1
        return self.seq

    def wrap(self, tick: int) -> int:
        """A tick as the link carries it in STATUS (CAN: its low byte)."""
        return tick % (256 if self.can else 2**32)

    def same_tick(self, status_tick: int, k: int) -> bool:
        return self.wrap(status_tick - k) == 0

    # helpers on answers ---------------------------------------------------------
    @staticmethod
    def statuses(answers) -> list:
        return [m for m in answers if isinstance(m, P.Status)]

    @staticmethod
    def nacks(answers, reason=None) -> list:
        return [m for m in answers if isinstance(m, P.Nack) and (reason is None or m.reason == reason)]

    def last_status(self, per_tick) -> P.Status | None:
        for answers in reversed(per_tick):
            s = self.statuses(answers)
            if s:
                return s[-1]
        return None

    def wait_nack(self, seconds: float = 0.2) -> list:
        return self.nacks(self.collect(time.monotonic() + seconds))


def run_checks(link, node: int) -> dict:
    """Every check against node over link; the report as a dict."""
    t = Tester(link, node)
    started = time.monotonic()
    for phase in (_start, _loudness, _config, _following, _watchdog, _estop_and_wrap, _refused, _reopen):
        try:
            phase(t)
        except _Abort as exc:           # the node did not answer: later phases cannot run
            t.check(exc.section, exc.name, False, str(exc))
            break
        except (AttributeError, TypeError, IndexError, KeyError) as exc:    # an answer missing
            t.check("tester", f"the checks of {phase.__name__.strip('_')} ran to the end", False,
                    f"an answer the checks needed did not come ({type(exc).__name__}: {exc})")
    sections: dict[str, list] = {}
    for c in t.checks:
        sections.setdefault(c.section, []).append(asdict(c))
    failed = sum(not c.ok for c in t.checks)
    return {"link": link.protocol, "node": node, "checks": len(t.checks), "failed": failed,
            "passed": len(t.checks) - failed, "seconds": round(time.monotonic() - started, 2),
            "figures": t.figures, "sections": sections}


class _Abort(Exception):
    def __init__(self, section: str, name: str, text: str):
        super().__init__(text)
        self.section, self.name = section, name


def _start(t: Tester) -> None:
    answers = []
    while len(answers) < START_TICKS and not any(t.statuses(a) for a in answers):
        answers.append(t.sync(setpoints=False))
    answers += t.ticks(4, setpoints=False)
    got = [i for i, a in enumerate(answers) if t.statuses(a)]
    if not got:
        raise _Abort("6 SYNC", "the node answers SYNC with STATUS",
                     f"no STATUS from node {t.node} in {len(answers)} ticks")
    first_status = next(m for m in answers[got[0]] if isinstance(m, P.Status))
    t.figures["first_answer_ticks"] = got[0]
    t.check("6 SYNC", f"first STATUS within {FIRST_ANSWER_TICKS} ticks of the first SYNC",
            got[0] <= FIRST_ANSWER_TICKS and t.same_tick(first_status.tick, 0),
            f"first STATUS after {got[0]} ticks, for tick {first_status.tick}")
    ticks = [s.tick for a in answers for s in t.statuses(a)]
    t.check("6 SYNC", "one STATUS per SYNC, seq = the SYNC's tick",
            ticks == [k % (256 if t.can else 2**32) for k in range(ticks[0], len(answers))],
            f"STATUS ticks {ticks} for SYNCs 0..{len(answers) - 1}")
    t.check("6 SYNC", "PRE_OPERATIONAL before any setpoint",
            first_status.state == P.STATE_PRE_OPERATIONAL, f"state 0x{first_status.state:02x}")
    t.start = list(first_status.positions)
    t.answered = True
    beats = [m for a in answers for m in a if isinstance(m, P.Heartbeat)]
    t.check("6 HEARTBEAT", "HEARTBEAT(BOOT) first after start",
            bool(beats) and beats[0].state == P.STATE_BOOT and (t.can or beats[0].seq == 0),
            f"heartbeats {[(b.state, b.seq) for b in beats]} (needs a freshly started node)")
    if not t.can:
        t.check("6 HEARTBEAT", "the change from BOOT reported, seq counting up",
                len(beats) >= 2 and beats[1].state == first_status.state
                and [b.seq for b in beats] == list(range(beats[0].seq, beats[0].seq + len(beats))),
                f"heartbeats {[(b.state, b.seq) for b in beats]}")
        k = t.tick
        polled = t.sync(setpoints=False, poll=(t.node + 1) % 255)
        t.check("4 SYNC", "a SYNC polling another node is not answered", not t.statuses(polled),
                f"STATUS {t.statuses(polled)} to SYNC {k} polling node {(t.node + 1) % 255}")
    t.channels = len(t.start)
    if not t.check("4 STATUS", "the node reports at least one channel", t.channels > 0, "0 channels"):
        raise _Abort("4 STATUS", "channels", "no channel to test")


def _loudness(t: Tester) -> None:
    """A node that measures music answers each SYNC with one LOUDNESS after
    its STATUS, counting its frames, always in the same form; a node that
    sends none is not checked here."""
    refused = t.link.refused()
    answers = t.ticks(LOUDNESS_TICKS, setpoints=False)
    frames = [m for a in answers for m in a if isinstance(m, P.Loudness)]
    if not frames and t.link.refused() == refused:
        t.figures["loudness"] = "none (the node does not measure music)"
        return
    forms = sorted({-1 if m.bands is None else len(m.bands) for m in frames})
    t.figures["loudness"] = ", ".join("the loudness alone" if k < 0 else f"{k} bands" for k in forms)
    t.check("4 LOUDNESS", "every LOUDNESS frame decodes (lengths, band counts, values)",
            t.link.refused() == refused, f"{t.link.refused() - refused} frames refused")
    t.check("4 LOUDNESS", "every frame in the same form (the loudness alone, or as many bands)",
            len(forms) == 1, f"forms {t.figures['loudness']}")
    t.check("6 LOUDNESS", f"one LOUDNESS per SYNC answered ({LOUDNESS_TICKS} SYNCs)",
            abs(len(frames) - LOUDNESS_TICKS) <= 1, f"{len(frames)} LOUDNESS frames")
    counters = [m.frame for m in frames]
    t.check("6 LOUDNESS", "the frame counter counts up by one",
            counters == [(counters[0] + i) % 2**32 for i in range(len(counters))] if counters else False,
            f"frame counters {counters}")
    order = [[type(m) for m in a if isinstance(m, (P.Status, P.Loudness))] for a in answers]
    t.check("6 LOUDNESS", "LOUDNESS after the STATUS of the same answer",
            all(o.index(P.Loudness) > o.index(P.Status) for o in order if P.Loudness in o and P.Status in o),
            f"answers {[[k.__name__ for k in o] for o in order]}")


def _config_message(t: Tester, watchdog=WATCHDOG_TICKS, channels=None, **change) -> P.Config:
    chans = [P.ChannelConfig(c, p - LIMIT_SPAN, p + LIMIT_SPAN, 10**7, 10**8)
             for c, p in enumerate(t.start)] if channels is None else channels
    return P.Config(t.node, tuple(chans), watchdog, round(TICK * 1e6), t.command_seq(), **change)


def _expect_nack(t: Tester, section: str, name: str, reason: int, ref_type: int, ref_seq: int | None,
                 send) -> None:
    send()
    nacks = t.wait_nack()
    ok = [n for n in nacks if n.reason == reason and n.ref_type == ref_type
          and (ref_seq is None or n.ref_seq == ref_seq)]
    t.check(section, name, len(ok) == 1 and len(nacks) == 1,
            f"NACKs {[(P.REASONS.get(n.reason, n.reason), n.ref_type, n.ref_seq) for n in nacks]}, "
            f"expected one {P.REASONS.get(reason, reason)} for type 0x{ref_type:02x} seq {ref_seq}")


def _config(t: Tester) -> None:
    good = _config_message(t)
    _expect_nack(t, "4 CONFIG", "a valid CONFIG is answered ACCEPTED", P.REASON_ACCEPTED, P.CONFIG,
                 good.seq, lambda: t.link.send(good))
    c0 = t.start[0]
    bad = _config_message(t, channels=[P.ChannelConfig(0, c0 + 10, c0 - 10, 1000, 1000)])
    _expect_nack(t, "4 CONFIG", "min > max is refused BAD_CONFIG", P.REASON_BAD_CONFIG, P.CONFIG,
                 bad.seq, lambda: t.link.send(bad))
    zero = _config_message(t, watchdog=0)
    _expect_nack(t, "4 CONFIG", "a watchdog of 0 is refused BAD_CONFIG", P.REASON_BAD_CONFIG, P.CONFIG,
                 zero.seq, lambda: t.link.send(zero))
    missing = (P.CAN_CHANNELS - 1) if t.can else 255
    if t.channels <= missing:
        other = _config_message(t, channels=[P.ChannelConfig(missing, 0, 10, 1000, 1000)])
        _expect_nack(t, "4 CONFIG", "a channel the node lacks is refused BAD_CHANNEL",
                     P.REASON_BAD_CHANNEL, P.CONFIG, other.seq, lambda: t.link.send(other))
    if not t.can:
        return
    frames = P.encode_can(_config_message(t))
    cid = P.CAN_CONFIG + t.node

    def send(fs):
        return lambda: [t.link.send_frame(i, d) for i, d in fs]
    seq = int.from_bytes(frames[-1][1][4:], "little")
    _expect_nack(t, "5 CAN CONFIG", "a missing ACCEL is CONFIG_INCOMPLETE", P.REASON_CONFIG_INCOMPLETE,
                 P.CONFIG, seq, send([f for f in frames if f[1][:2] != bytes([0x13, 0])]))
    one = P.encode_can(_config_message(t, channels=[P.ChannelConfig(0, c0 - LIMIT_SPAN, c0 + LIMIT_SPAN,
                                                                    10**7, 10**8)]))
    apply = bytearray(one[-1][1])
    apply[1] = 2                                        # announces 2 channels after 1
    seq = int.from_bytes(apply[4:], "little")
    _expect_nack(t, "5 CAN CONFIG", "APPLY announcing 2 channels after 1 is CONFIG_INCOMPLETE",
                 P.REASON_CONFIG_INCOMPLETE, P.CONFIG, seq, send(one[:-1] + [(cid, bytes(apply))]))
    _expect_nack(t, "5 CAN CONFIG", "APPLY without BEGIN is CONFIG_INCOMPLETE",
                 P.REASON_CONFIG_INCOMPLETE, P.CONFIG, seq, send([(cid, bytes(apply[:1]) + b"\0"
                                                                   + bytes(apply[2:]))]))
    _expect_nack(t, "5 CAN CONFIG", "WATCHDOG above 65535 is BAD_VALUE", P.REASON_BAD_VALUE, P.CONFIG,
                 None, send([frames[0], (cid, bytes.fromhex("02ff000000000100"))]))
    _expect_nack(t, "5 CAN CONFIG", "BEGIN with a channel other than 0xFF is BAD_VALUE",
                 P.REASON_BAD_VALUE, P.CONFIG, None, send([(cid, b"\x01\x00" + frames[0][1][2:])]))
    again = _config_message(t)
    _expect_nack(t, "5 CAN CONFIG", "a whole configuration after refused ones is ACCEPTED",
                 P.REASON_ACCEPTED, P.CONFIG, again.seq, lambda: t.link.send(again))


def _following(t: Tester) -> None:
    t.targets = list(t.start)
    per_tick = t.ticks(3)
    s = t.last_status(per_tick)
    t.check("6 SETPOINT", "OPERATIONAL once setpoints come", s is not None and s.state == P.STATE_OPERATIONAL,
            f"status {s}")
    beats = [m for a in per_tick for m in a if isinstance(m, P.Heartbeat)]
    t.check("6 HEARTBEAT", "a HEARTBEAT at the change to OPERATIONAL",
            any(b.state == P.STATE_OPERATIONAL for b in beats), f"heartbeats {beats}")
    t.targets[0] = t.start[0] + STEP
    per_tick = t.ticks(15)
    s = t.last_status(per_tick)
    moved = s is not None and t.start[0] < s.positions[0] <= t.start[0] + STEP
    t.check("6 Following", f"channel 0 moves towards a setpoint {STEP} counts away", moved,
            f"from {t.start[0]} to {s.positions[0] if s else None}")
    # LIMIT: one setpoint beyond max, then back inside
    t.targets[0] = t.start[0] + LIMIT_SPAN + 100
    t.sync()
    t.targets[0] = t.start[0] + STEP
    after = t.ticks(2)
    flags = [s.flags for a in after for s in t.statuses(a)]
    t.check("6 SETPOINT", "a setpoint beyond max sets LIMIT in the next STATUS, which clears it",
            len(flags) == 2 and flags[0] & P.FLAG_LIMIT and not flags[1] & P.FLAG_LIMIT,
            f"flags {[hex(f) for f in flags]}")
    # seq gaps: three ticks without setpoints
    before = t.last_status(after)
    t.ticks(3, setpoints=False)
    per_tick = t.ticks(2)
    s = t.last_status(per_tick)
    t.check("6 SETPOINT", "3 ticks without a setpoint add 3 seq gaps",
            s is not None and (s.seq_gaps - before.seq_gaps) % 65536 == 3,
            f"seq gaps {before.seq_gaps} -> {s.seq_gaps if s else None}")
    # a setpoint for a channel the node lacks
    missing = P.CAN_CHANNELS - 1 if t.can else 255
    if t.channels <= missing:
        k = t.tick
        answers = t.sync(extra=lambda: t.link.send(P.Setpoints(k, [(t.node, missing, 0)]))) + t.sync()
        nacks = t.nacks(answers, P.REASON_BAD_CHANNEL)
        t.check("6 SETPOINT", "a setpoint for a channel the node lacks is NACKed BAD_CHANNEL",
                len(nacks) == 1 and nacks[0].ref_type == P.SETPOINT, f"NACKs {t.nacks(answers)}")
    # stale: a setpoint older than the last accepted (serial), or of another tick's counter (CAN)
    before = t.last_status(t.ticks(1))
    k = t.tick
    if t.can:
        stale = [(i, bytes([(d[0] & 0xF0) | ((k + 5) & 0xF)]) + d[1:])
                 for i, d in P.encode_can(P.Setpoints(k, [(t.node, 0, t.start[0] - STEP)]))]
        answers = t.sync(extra=lambda: [t.link.send_frame(i, d) for i, d in stale]) + t.sync()
        t.check("5 CAN PDOs", "a setpoint PDO of another tick is NACKed STALE",
                len(t.nacks(answers, P.REASON_STALE)) == 1, f"NACKs {t.nacks(answers)}")
    else:
        old = P.Setpoints((k - 3) % 2**32, [(t.node, 0, t.start[0] - STEP)])
        answers = t.sync(extra=lambda: t.link.send(old)) + t.sync()
    s = t.last_status([answers])
    t.check("6 SETPOINT", "a stale setpoint is ignored and counted in rejected",
            s is not None and (s.rejected - before.rejected) % 65536 == 1 and s.positions[0] > t.start[0],
            f"rejected {before.rejected} -> {s.rejected if s else None}, channel 0 at "
            f"{s.positions[0] if s else None}")


def _watchdog(t: Tester) -> None:
    last = t.sent_at[t.wrap(t.tick - 1)]        # when the last setpoint went [s]
    t.targets, saved = None, t.targets
    per_tick = t.ticks(WATCHDOG_TICKS + 4, setpoints=False)
    # judged by time, as the node does: STATUS answers the SYNC sent dt after
    # the last setpoint; WATCHDOG may be set once dt reaches the watchdog
    # time (less the way there), and must be WATCHDOG_SLACK ticks later
    limit = WATCHDOG_TICKS * TICK
    seen = [(t.sent_at[t.wrap(s.tick)] - last, bool(s.flags & P.FLAG_WATCHDOG))
            for a in per_tick for s in t.statuses(a) if t.wrap(s.tick) in t.sent_at]
    early = [round(dt * 1e3) for dt, flag in seen if flag and dt < limit - WAY]
    late = [round(dt * 1e3) for dt, flag in seen if not flag and dt > limit + WATCHDOG_SLACK * TICK]
    t.check("6 Watchdog", f"WATCHDOG set {WATCHDOG_TICKS} ticks ({limit * 1e3:.0f} ms) after the last "
            "setpoint, not before", any(flag for _, flag in seen) and not early and not late,
            f"set at {early} ms, or not yet at {late} ms, after the last setpoint")
    s = t.last_status(per_tick)
    t.check("6 Watchdog", "PRE_OPERATIONAL once the watchdog tripped",
            s is not None and s.state == P.STATE_PRE_OPERATIONAL, f"state {s.state if s else None}")
    t.targets = saved
    per_tick = t.ticks(2)
    s = t.last_status(per_tick)
    t.check("6 Watchdog", "the next setpoint clears WATCHDOG and the node follows again",
            s is not None and not s.flags & P.FLAG_WATCHDOG and s.state == P.STATE_OPERATIONAL,
            f"status {s}")


def _estop_and_wrap(t: Tester) -> None:
    for node, what in ((t.node, "to the node"), (P.BROADCAST, "to every node")):
        answers = t.sync(extra=lambda: t.link.send(P.Estop(node, t.command_seq()))) + t.sync()
        s = t.last_status([answers])
        t.check("6 E-stop", f"ESTOP {what} latches: ESTOP flag, STOPPED",
                s is not None and s.flags & P.FLAG_ESTOP and s.state == P.STATE_STOPPED, f"status {s}")
        per_tick = t.ticks(WATCHDOG_TICKS + 3)
        latched = t.nacks([m for a in [answers] + per_tick for m in a], P.REASON_ESTOP_LATCHED)
        t.check("6 E-stop", "setpoints while latched: one NACK ESTOP_LATCHED",
                len(latched) == 1 and latched[0].ref_type == P.SETPOINT, f"NACKs {latched}")
        s = t.last_status(per_tick)
        t.check("6 E-stop", "latched: setpoints ignored, the watchdog does not act",
                s is not None and s.state == P.STATE_STOPPED and not s.flags & P.FLAG_WATCHDOG,
                f"status {s}")
        if node == P.BROADCAST:
            break
        t.sync(extra=lambda: t.link.send(P.Estop(t.node, t.command_seq())))
        s = t.last_status(t.ticks(1))
        t.check("6 E-stop", "a second ESTOP changes nothing", s is not None and s.state == P.STATE_STOPPED,
                f"status {s}")
        t.sync(extra=lambda: t.link.send(P.EstopRelease(t.node, t.command_seq())))
        s = t.last_status(t.ticks(2))
        t.check("6 E-stop", "ESTOP_RELEASE clears the latch, then setpoints are followed",
                s is not None and not s.flags & P.FLAG_ESTOP and s.state == P.STATE_OPERATIONAL,
                f"status {s}")
    # the seq wrap, while latched: the host "restarts" near 2^32 (a SYNC not
    # newer than the last), releases, and runs across the wrap
    gaps = t.last_status(t.ticks(1)).seq_gaps
    t.tick = WRAP_FROM
    t.sync(setpoints=False, extra=lambda: t.link.send(P.EstopRelease(P.BROADCAST, t.command_seq())))
    per_tick = t.ticks(6)
    st = [s for a in per_tick for s in t.statuses(a)]
    t.check("6 E-stop", "ESTOP_RELEASE to every node releases", bool(st) and not st[-1].flags & P.FLAG_ESTOP,
            f"statuses {st[-1:]}")
    t.check("2 Conventions", "seq wraps from 2^32-1 to 0: statuses follow the tick, no gaps, no refusals",
            [s.tick % (256 if t.can else 2**32) for s in st]
            == [(WRAP_FROM + 1 + i) % (256 if t.can else 2**32) for i in range(6)]
            and st[-1].seq_gaps == gaps and st[-1].state == P.STATE_OPERATIONAL,
            f"ticks {[s.tick for s in st]}, seq gaps {gaps} -> {st[-1].seq_gaps if st else None}")


def _refused(t: Tester) -> None:
    """Refused frames: NACKed by the node addressed alone, counted, never
    for a bad CRC or another node's frame."""
    def probe(name, send, reason, counted, section="6 Receiving"):
        before = t.last_status(t.ticks(1))
        last_sync = (t.tick - 1) % 2**32
        answers = t.sync(extra=send) + t.sync()
        s = t.last_status([answers])
        nacks = t.nacks(answers)
        ok_nack = (not nacks) if reason is None else (
            len(nacks) == 1 and nacks[0].reason == reason and (t.can or nacks[0].seq in (last_sync, t.tick - 2)))
        ok_count = s is not None and before is not None and (s.rejected - before.rejected) % 65536 == counted
        t.check(section, name, ok_nack and ok_count,
                f"NACKs {[(P.REASONS.get(n.reason, n.reason), n.seq) for n in nacks]}, rejected "
                f"{before.rejected if before else None} -> {s.rejected if s else None}")

    if t.can:
        cid = P.CAN_CONFIG + t.node
        other = P.CAN_CONFIG + (t.node % P.CAN_NODE_MAX) + 1
        probe("a frame of a wrong DLC to the node: NACK BAD_LENGTH, counted",
              lambda: t.link.send_frame(cid, b"\x01\xff\x00\x00\x20\x4e\x00"), P.REASON_BAD_LENGTH, 1)
        probe("reserved bytes not 0: NACK BAD_VALUE, counted",
              lambda: t.link.send_frame(cid, b"\x10\x00\x01\x00\x00\x00\x00\x00"), P.REASON_BAD_VALUE, 1)
        probe("a refused frame to another node: no NACK, not counted",
              lambda: t.link.send_frame(other, b"\x01\xff\x00\x00\x20\x4e\x00"), None, 0)
        probe("a refused broadcast (SYNC of DLC 2): no NACK, counted",
              lambda: t.link.send_frame(P.CAN_SYNC, bytes([(t.tick - 1) & 0xFF, 0])), None, 1)
        return
    estop = P.encode_body(P.Estop(t.node, 4242))[:-4]
    bad_crc = bytearray(P.encode_body(P.Estop(t.node, 4243)))
    bad_crc[-1] ^= 0x10
    probe("bad CRC: no NACK, counted", lambda: t.link.send_bytes(P.cobs_encode(bytes(bad_crc)) + b"\0"),
          None, 1, "3.3 Receiving")
    probe("too long (300 bytes before a 0x00): no NACK, counted",
          lambda: t.link.send_bytes(b"\x01" * 300 + b"\0"), None, 1, "3.3 Receiving")
    probe("version 2 to the node: NACK BAD_VERSION, counted",
          lambda: t.link.send_bytes(sealed(b"\x02" + estop[1:])), P.REASON_BAD_VERSION, 1, "8 Versions")
    probe("unknown type to the node: NACK BAD_TYPE, counted",
          lambda: t.link.send_bytes(sealed(estop[:1] + b"\x42" + estop[2:])), P.REASON_BAD_TYPE, 1, "4 Messages")
    probe("wrong payload length to the node: NACK BAD_LENGTH, counted",
          lambda: t.link.send_bytes(sealed(estop + b"\x00")), P.REASON_BAD_LENGTH, 1, "4 Messages")
    sync = P.encode_body(P.Sync(t.tick))[:-4]
    probe("a SYNC with the node's address: NACK BAD_VALUE, counted",
          lambda: t.link.send_bytes(sealed(sync[:2] + bytes([t.node]) + sync[3:])), P.REASON_BAD_VALUE, 1,
          "4 Messages")
    probe("a refused frame to another node: no NACK, not counted",
          lambda: t.link.send_bytes(sealed(b"\x02" + estop[1:2] + bytes([(t.node + 1) % 255]) + estop[3:])),
          None, 0)
    probe("a refused broadcast: no NACK, counted",
          lambda: t.link.send_bytes(sealed(b"\x02" + estop[1:2] + b"\xff" + estop[3:])), None, 1)
    s = t.last_status(t.ticks(1))
    t.check("6 E-stop", "refused ESTOP frames latched nothing", s is not None and not s.flags & P.FLAG_ESTOP,
            f"status {s}")


def _reopen(t: Tester) -> None:
    t.targets = None
    t.link.close()
    t.link.open()
    answers = t.ticks(FIRST_ANSWER_TICKS + 1, setpoints=False)
    t.check("3.3 Receiving", "answers again after the host closed and reopened the link",
            any(t.statuses(a) for a in answers), "no STATUS after reopening")


# -- the report ---------------------------------------------------------------

def format_report(report: dict) -> str:
    lines = [f"servo node {report['node']} over {report['link']}: conformance to firmware_protocol/SPEC.md"]
    for section in sorted(report["sections"], key=lambda s: [int(x) if x.isdigit() else x
                                                            for x in s.split()[0].split(".")]):
        checks = report["sections"][section]
        passed = sum(c["ok"] for c in checks)
        lines.append(f"section {section}: {passed}/{len(checks)} passed")
        for c in checks:
            lines.append(f"  {'ok  ' if c['ok'] else 'FAIL'} {c['name']}" + (f": {c['detail']}" if c["detail"] else ""))
    f = report["figures"]
    if "first_answer_ticks" in f:
        lines.append(f"first STATUS {f['first_answer_ticks']} ticks after the first SYNC")
    if "loudness" in f:
        lines.append(f"LOUDNESS: {f['loudness']}")
    lines.append(f"{report['passed']}/{report['checks']} checks passed in {report['seconds']} s"
                 + ("" if not report["failed"] else f"; {report['failed']} FAILED"))
    return "\n".join(lines)
