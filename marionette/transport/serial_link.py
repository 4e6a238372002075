"""Servo nodes on a serial line (RS-232/RS-485, a USB adapter, a pty, or
any pyserial URL such as loop:// or socket://host:port).

Setpoints: when the port has a file descriptor, the C tick writes the
COBS frames itself, without the GIL (the fast path); otherwise the engine
queues them and its sender thread calls write(). Status, heartbeat and
error frames coming back are deframed by the C codec on a receive thread
and handed to a NodeMonitor.
"""
from __future__ import annotations

import io
import threading

import serial

from marionette import protocol
from marionette.transport.node_monitor import NodeMonitor

DEFAULT_BAUDRATE = 1_000_000        # [baud]
READ_TIMEOUT = 0.01                 # receive thread poll [s]


class SerialLink:
    protocol = "serial"

    def __init__(self, url: str, baudrate: int = DEFAULT_BAUDRATE):
        self.url = url
        try:
            self.port = serial.serial_for_url(url, baudrate=baudrate, timeout=READ_TIMEOUT,
                                              write_timeout=0.1)
        except (serial.SerialException, ValueError) as exc:
            raise OSError(f"serial link {url}: {exc}") from None
        self.deframer = protocol.Deframer()
        self.monitor: NodeMonitor | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._write_lock = threading.Lock()

    def fileno(self) -> int | None:
        """The port's descriptor for the fast path, or None (loop://, socket://...)."""
        try:
            return self.port.fileno()
        except (AttributeError, io.UnsupportedOperation, serial.SerialException):
            return None

    def write(self, frames: bytes) -> None:
        """Frames from the engine's ring, or a control message, in one write."""
        with self._write_lock:
            self.port.write(frames)

    def send(self, message) -> None:
        """Encode and send one protocol message (ESTOP, CONFIG...)."""
        self.write(protocol.encode_serial(message))

    def start_receiving(self, monitor: NodeMonitor) -> None:
        self.monitor = monitor
        self._thread = threading.Thread(target=self._receive, name="marionette-serial-rx",
                                        daemon=True)
        self._thread.start()

    def _receive(self) -> None:
        while not self._stop.is_set():
            try:
                data = self.port.read(4096)
            except (serial.SerialException, OSError, TypeError):
                if self._stop.is_set():
                    return
                self.monitor.events.append((0.0, f"serial link {self.url}: read failed"))
                return
            if not data:
                continue
            before = self.deframer.rejected
            for message in self.deframer.feed(data):
                self.monitor.take(message)
            if self.deframer.rejected != before:
                self.monitor.on_bad_frame(self.deframer.rejected - before)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(1.0)
        self.port.close()
