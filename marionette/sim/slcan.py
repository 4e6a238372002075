"""An slcan (Lawicel ASCII) CAN adapter emulated on a pty, so python-can's
`slcan` interface in another process talks to simulated nodes as it would
to a USB-CAN dongle.

Only classic 11- and 29-bit data frames are carried; the adapter's set-up
commands (bit rate, open, close, version) are acknowledged with CR.
"""
from __future__ import annotations

import os

from marionette.errors import ArgumentError

CR = b"\r"
BELL = b"\x07"          # the adapter's "error" answer


class SlcanAdapter:
    """The adapter side of an slcan line: bytes in, CAN frames out, and back.

    feed(data) returns the (can_id, data) frames the host sent; encode()
    makes the line for a frame going to the host."""

    def __init__(self):
        self._line = bytearray()
        self._discarding = False            # inside a runaway line: skip to the next CR
        self.is_open = False
        self.bitrate_code = None
        self.bad_lines = 0                  # lines the adapter did not understand

    def feed(self, data: bytes) -> tuple[list[tuple[int, bytes]], bytes]:
        """Frames received, and the answer bytes to write back."""
        frames, answer = [], bytearray()
        for b in data:
            if b in (0x0D, 0x07):
                line, self._line = bytes(self._line), bytearray()
                if self._discarding:
                    self._discarding = False
                elif line:
                    frame, reply = self._command(line)
                    if frame is not None:
                        frames.append(frame)
                    answer += reply
            elif self._discarding:
                continue
            elif len(self._line) < 64:
                self._line.append(b)
            else:                           # runaway line: drop it, resynchronise on CR
                self._line.clear()
                self._discarding = True
                self.bad_lines += 1
        return frames, bytes(answer)

    def _command(self, line: bytes):
        kind = chr(line[0])
        try:
            if kind in "tT":
                width = 3 if kind == "t" else 8
                can_id = int(line[1:1 + width], 16)
                dlc = int(line[1 + width:2 + width])
                payload = bytes.fromhex(line[2 + width:2 + width + 2 * dlc].decode())
                if dlc > 8 or len(payload) != dlc:
                    raise ArgumentError(line)
                return ((can_id, payload) if self.is_open else None), CR
            if kind == "O" or kind == "L":
                self.is_open = True
                return None, CR
            if kind == "C":
                self.is_open = False
                return None, CR
            if kind in "Ss":
                self.bitrate_code = line[1:].decode()
                return None, CR
            if kind == "V":
                return None, b"V0101" + CR
            if kind == "N":
                return None, b"NSIM0" + CR
            if kind in "FZXWMm":
                return None, CR
        except ValueError:
            pass
        self.bad_lines += 1
        return None, BELL

    @staticmethod
    def encode(can_id: int, data: bytes) -> bytes:
        """The line a received bus frame reaches the host as."""
        if can_id < 0x800:
            head = f"t{can_id:03X}{len(data):d}"
        else:
            head = f"T{can_id:08X}{len(data):d}"
        return (head + data.hex().upper()).encode() + CR


class Pty:
    """A pty pair in raw mode: the simulator keeps the master; a host opens
    `path` (the slave) with pyserial. The simulator also holds the slave
    open, so the master never sees a hang-up while no host is connected."""

    def __init__(self):
        import tty
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.path = os.ttyname(self._slave)

    def close(self) -> None:
        for fd in (self.master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
