"""Servo nodes on a CAN bus, through any python-can interface (socketcan,
pcan, kvaser, slcan, virtual, udp_multicast...).

Setpoints: the C tick encodes each tick's CAN frames (SYNC and setpoint
PDOs, firmware_protocol/SPEC.md) into the engine's ring, and the engine's
sender thread hands them to bus.send(); on SocketCAN the tick writes them
to the socket itself. Status, heartbeat and EMCY frames
coming back are decoded by the C codec on a receive thread and handed to a
NodeMonitor.

A bus that is gone is noticed by its reads or writes: an error that says
so for good (an errno such as EIO: slcan's pty or USB adapter gone), or
every frame of FAILED_TICKS ticks refused (a bus with no node to acknowledge).
Then `gone` holds the errno, and the engine's sender tells the tick, which
counts every node silent at once, as it does when its own write() to a
serial link fails.
"""
from __future__ import annotations

import errno
import threading
import time

import can

from marionette import _core, protocol
from marionette.transport.node_monitor import SILENT_AFTER_TICKS, NodeMonitor

RECV_TIMEOUT = 0.01         # receive thread poll [s]
FAILED_TICKS = SILENT_AFTER_TICKS   # ticks whose every frame failed: the bus is gone [ticks]


def _errno(exc: BaseException) -> int:
    """The errno behind a python-can error (its cause or context, e.g. the
    OSError under pyserial's SerialException), 0 if none."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, OSError) and exc.errno:
            return exc.errno
        exc = exc.__cause__ or exc.__context__
    return 0


class CanLink:
    protocol = "can"

    def __init__(self, bus: can.BusABC | None = None, **bus_kwargs):
        """Wrap a bus, or open one: CanLink(interface="slcan", channel="/dev/ttyACM0", bitrate=500000)."""
        if bus is None:
            if bus_kwargs.get("interface") == "slcan":
                bus_kwargs.setdefault("sleep_after_open", 0.0)
            if bus_kwargs.get("interface") == "socketcan":
                # the tick writes to the socket itself: the receive thread must
                # see those SYNCs to unwrap the 8-bit ticks of the statuses
                bus_kwargs.setdefault("receive_own_messages", True)
            where = f"can:{bus_kwargs.get('interface')}:{bus_kwargs.get('channel')}" + (
                f"@{bus_kwargs['bitrate']}" if "bitrate" in bus_kwargs else "")
            try:
                bus = can.Bus(**bus_kwargs)
            except (can.CanError, OSError, ValueError, ImportError) as exc:
                raise OSError(f"CAN link {where}: {exc}") from None
        self.bus = bus
        self.monitor: NodeMonitor | None = None
        self.decoder = protocol.CanDecoder()    # also fed our own SYNCs: it unwraps STATUS ticks
        self._decoder_lock = threading.Lock()
        self.send_errors = 0
        self.gone = 0                       # errno once the bus is gone for good (latched)
        self._failed_ticks = 0              # ticks in a row whose every frame failed
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    def fileno(self) -> int | None:
        """A SocketCAN socket's descriptor, to which the tick writes its CAN
        records itself (struct can_frame, one per write); None for every other
        interface, whose frames go through python-can's send()."""
        sock = getattr(self.bus, "socket", None)
        if type(self.bus).__name__ == "SocketcanBus" and sock is not None:
            return sock.fileno()
        return None

    def write(self, records: bytes) -> None:
        """Send the CAN frames of a tick taken from the engine's ring."""
        sent = [self.send_frame(can_id, data) for can_id, data in protocol.can_records(records)]
        self._failed_ticks = 0 if any(sent) else self._failed_ticks + 1
        if self._failed_ticks >= FAILED_TICKS and not self.gone:
            self.gone = errno.EIO

    def send_frame(self, can_id: int, data: bytes) -> bool:
        """True if python-can took the frame."""
        if can_id == protocol.CAN_SYNC:
            with self._decoder_lock:
                self.decoder.feed(can_id, data)
        if self.gone:                       # no use: every write fails
            self.send_errors += 1
            return False
        try:
            self.bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
            return True
        except can.CanError as exc:
            self.send_errors += 1
            err = _errno(exc)
            if err and _core.receiver_gone(err):
                self.gone = err
            return False

    def send(self, message) -> None:
        """Encode and send one protocol message (ESTOP, CONFIG...)."""
        for can_id, data in protocol.encode_can(message):
            self.send_frame(can_id, data)

    def start_receiving(self, monitor: NodeMonitor) -> None:
        self.monitor = monitor
        self._thread = threading.Thread(target=self._receive, name="marionette-can-rx", daemon=True)
        self._thread.start()

    def _receive(self) -> None:
        while not self._stop.is_set():
            try:
                msg = self.bus.recv(RECV_TIMEOUT)
            except (can.CanError, OSError, ValueError) as exc:
                if self._stop.is_set():
                    return
                err = _errno(exc)
                if err and _core.receiver_gone(err):    # e.g. EIO: slcan's pty or adapter gone
                    self.gone = self.gone or err
                    return
                time.sleep(RECV_TIMEOUT)                # a passing error: no busy loop
                continue
            if msg is None or msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id:
                continue
            with self._decoder_lock:
                before = self.decoder.rejected
                messages = self.decoder.feed(msg.arbitration_id, bytes(msg.data))
                bad = self.decoder.rejected - before
            if bad:
                self.monitor.on_bad_frame(bad)
            for message in messages:
                self.monitor.take(message)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(1.0)
        try:
            self.bus.shutdown()
        except (can.CanError, OSError):
            if not self.gone:                           # a bus that is gone cannot be told
                raise
