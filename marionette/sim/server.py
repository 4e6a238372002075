"""The simulator process: simulated nodes behind a real serial line or CAN
bus, on wall-clock time.

Front ends:
* serial: a pty speaking the serial protocol (COBS frames); the host opens
  the printed path with pyserial;
* slcan: a pty emulating an slcan CAN adapter; the host opens it with
  python-can's `slcan` interface;
* udp_multicast: python-can's udp_multicast bus (needs msgpack).

Control lines on stdin change the faults at run time (see Faults.apply) or
end the run ('quit'); each answer is one JSON line on stdout. `marionette
sim` reads them from a pipe, or from its terminal while it is in the
terminal's foreground; in the background (`marionette sim --serial &`) it
leaves the terminal alone.
"""
from __future__ import annotations

import heapq
import json
import os
import select
import signal
import sys
import time

import numpy as np

from marionette import protocol
from marionette.sim.arrival import ArrivalClock
from marionette.sim.faults import Faults
from marionette.sim.figure import SimFigure
from marionette.sim.slcan import Pty, SlcanAdapter

LATE_S = 0.03               # input read this much later than the wait asked for: this process was late [s]
IDLE_ADVANCE = 0.02         # the drives run on (watchdogs, quick stops) at least this often [s]


def say(**fields) -> None:
    print(json.dumps(fields), flush=True)


class SerialFrontEnd:
    """Serial protocol on a pty."""

    def __init__(self):
        self.pty = Pty()
        self.fd = self.pty.master
        self.deframer = protocol.Deframer()
        self.address = {"serial": self.pty.path}

    def receive(self, faults: Faults) -> list:
        try:
            data = os.read(self.fd, 65536)
        except BlockingIOError:
            return []
        return self.deframer.feed(faults.mangle(data), refusals=True)

    def send(self, messages: list) -> None:
        if messages:
            _write_all(self.fd, b"".join(protocol.encode_serial(m) for m in messages))

    @property
    def rejected(self) -> int:
        """Frames refused before their header could be believed (content
        refusals come as protocol.Refused, for the node they address)."""
        return self.deframer.rejected - self.deframer.counters["decode_errors"]

    def counters(self) -> dict:
        return self.deframer.counters

    def close(self) -> None:
        self.pty.close()


class SlcanFrontEnd:
    """CAN frames through an slcan adapter emulated on a pty."""

    def __init__(self):
        self.pty = Pty()
        self.fd = self.pty.master
        self.adapter = SlcanAdapter()
        self.address = {"can": "slcan", "channel": self.pty.path}
        self.decoder = protocol.CanDecoder()
        self.frames_dropped = 0

    def receive(self, faults: Faults) -> list:
        try:
            data = os.read(self.fd, 65536)
        except BlockingIOError:
            return []
        frames, answer = self.adapter.feed(data)
        if answer:
            _write_all(self.fd, answer)
        return self._decode(frames, faults)

    def _decode(self, frames, faults: Faults) -> list:
        messages = []
        for can_id, payload in frames:
            # a CAN controller drops a frame whose CRC fails: corruption shows as loss
            if faults.rng.random() < faults.drop_rate + faults.corrupt_rate * 8 * (len(payload) + 6):
                self.frames_dropped += 1
                continue
            messages += self.decoder.feed(can_id, payload, refusals=True)
        return messages

    rejected = 0        # the CAN controller drops a bad frame; every refusal names its node

    def send(self, messages: list) -> None:
        lines = b"".join(SlcanAdapter.encode(can_id, data)
                         for m in messages for can_id, data in protocol.encode_can(m))
        if lines:
            _write_all(self.fd, lines)

    def counters(self) -> dict:
        return {**self.decoder.counters, "frames_dropped": self.frames_dropped,
                "bad_lines": self.adapter.bad_lines}

    def close(self) -> None:
        self.pty.close()


class UdpFrontEnd(SlcanFrontEnd):
    """CAN frames over python-can's udp_multicast bus."""

    def __init__(self, channel: str):
        import can
        self.bus = can.Bus(interface="udp_multicast", channel=channel, receive_own_messages=False)
        self.fd = self.bus.fileno()
        self.address = {"can": "udp_multicast", "channel": channel}
        self.decoder = protocol.CanDecoder()
        self.frames_dropped = 0

    def receive(self, faults: Faults) -> list:
        frames = []
        while (msg := self.bus.recv(0)) is not None:
            if not (msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id):
                frames.append((msg.arbitration_id, bytes(msg.data)))
        return self._decode(frames, faults)

    def send(self, messages: list) -> None:
        import can
        for m in messages:
            for can_id, data in protocol.encode_can(m):
                self.bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))

    def counters(self) -> dict:
        return {**self.decoder.counters, "frames_dropped": self.frames_dropped}

    def close(self) -> None:
        self.bus.shutdown()


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        try:
            n = os.write(fd, view)
        except BlockingIOError:
            select.select([], [fd], [], 0.01)
            continue
        view = view[n:]


def _in_foreground(tty) -> bool:
    try:
        return os.tcgetpgrp(tty.fileno()) == os.getpgrp()
    except OSError:
        return False


class _Stop(Exception):
    pass


def _stop_on_signal(signum, frame):
    raise _Stop


def run(figure: SimFigure, front, faults: Faults, seconds: float | None = None,
        trace_path: str | None = None, control=sys.stdin) -> dict:
    """Serve until 'quit' on stdin, SIGTERM or SIGINT, or seconds [s] pass."""
    os.set_blocking(front.fd, False)
    signal.signal(signal.SIGTERM, _stop_on_signal)
    say(ready=True, **front.address)
    t0 = time.monotonic()           # model time 0 [s, CLOCK_MONOTONIC]
    try:
        _serve(figure, front, faults, seconds, control, t0)
    except (_Stop, KeyboardInterrupt):
        pass
    figure.advance_to(time.monotonic() - t0)    # the watchdogs act up to the end
    summary = {"messages": figure.messages, "link": front.counters(),
               "bytes_dropped": faults.bytes_dropped, "bytes_corrupted": faults.bytes_corrupted,
               "nodes": {n: vars(s.counters) for n, s in figure.nodes.items()},
               "peak_accel": dict(zip(figure.config.axis_names, figure.peak_accel().tolist()))}
    if trace_path:
        np.savez(trace_path, t0=t0, **figure.trace_arrays())
    front.close()
    return summary


def _serve(figure: SimFigure, front, faults: Faults, seconds: float | None, control,
           t0: float) -> None:
    now = lambda: time.monotonic() - t0
    pending: list = []          # (due time [s], order, message): the delay fault
    arrival = ArrivalClock(figure.config.tick_period)
    looked = now()              # when the input was last read, or found empty [s]
    order = 0
    tty = control is not None and control.isatty()
    while seconds is None or now() < seconds:
        # a terminal is read only while it has us in its foreground (a read
        # from the background would stop the process: SIGTTIN)
        listen = control is not None and (not tty or _in_foreground(control))
        # sleep until input, a delayed message is due, or the drives' next
        # run (at most IDLE_ADVANCE: a terminal's foreground is checked again)
        wait = pending[0][0] - now() if pending else figure.time + IDLE_ADVANCE - now()
        timeout = min(max(wait, 0.0), IDLE_ADVANCE)                         # [s]
        readable, _, _ = select.select([front.fd] + ([control] if listen else []), [], [], timeout)
        returned = now()
        if front.fd in readable:
            messages = front.receive(faults)
            t = now()
            # input read much later than the input was last looked at plus the wait
            # asked for: this process was held off the CPU, and the input is timed
            # by the host's tick clock since then (arrival.py); else as read
            late = t - looked > timeout + LATE_S
            times = arrival.times(messages, looked if late else t, t)
            for m, at in zip(messages, times):
                heapq.heappush(pending, (at + faults.delay, order, m))
                order += 1
            looked = t
        else:
            looked = returned
        while pending and pending[0][0] <= now():
            due, _, m = heapq.heappop(pending)
            front.send(figure.handle(m, due, front.rejected))
        # control lines after the input read with them: 'quit' ends after the
        # frames that had already arrived
        if control is not None and control in readable:
            line = control.readline()
            if not line:                    # stdin closed: run on
                control = None
            elif line.strip() == "quit":
                return
            elif line.strip():
                try:
                    say(ok=faults.apply(line.strip()))
                except ValueError as exc:
                    say(error=str(exc))
        # no host: time goes on, as far as the input is known to have been empty
        # (not past a stall of this process, whose input is still to be read)
        if not pending and looked - figure.time > IDLE_ADVANCE:
            figure.advance_to(looked)
