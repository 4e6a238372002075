"""CSV recording of per-field LED detections, as an LED tracker delivers them.

Format
------
UTF-8 text, one detection per line, comma separated, with this header line::

    time_s,camera,led,R,T

* ``time_s`` - time of the video field [s] (float, finite, non-decreasing down the file);
* ``camera`` - camera index, an integer ``0 .. n_cameras-1`` (0 or 1 for two cameras);
* ``led``    - number of the LED strobed in this field, integer 1..4 (order of
  :mod:`marionette.teach.rucksack`);
* ``R``      - pixel column [pixel] (float or integer, finite);
* ``T``      - pixel row [pixel], counted *upwards* as in :mod:`marionette.teach.camera`.

One field (20 ms) shows one LED, so all lines with the same ``time_s`` carry the same
``led``, and each camera appears at most once per field.  A detection that a camera
missed is simply absent.  Blank lines and lines starting with ``#`` are ignored.

Errors raise :class:`RecordingError` (a ``ValueError``) naming the file, the line
number (1-based) and the offending value.
"""

from __future__ import annotations

import io
import math
import os
from dataclasses import dataclass

import numpy as np

from marionette.errors import ArgumentError, LineError, TeachError
from marionette.textfile import read_text

HEADER = ("time_s", "camera", "led", "R", "T")
N_LEDS = 4


class RecordingError(LineError):
    """Malformed recording."""


@dataclass
class Recording:
    """Detections in file order; all arrays (M,)."""

    time_s: np.ndarray    # field time [s]
    camera: np.ndarray    # camera index [1]
    led: np.ndarray       # LED number 1..4 [1]
    R: np.ndarray         # pixel column [pixel]
    T: np.ndarray         # pixel row, upwards [pixel]

    def __post_init__(self) -> None:
        self.time_s = np.asarray(self.time_s, float)
        self.camera = np.asarray(self.camera, int)
        self.led = np.asarray(self.led, int)
        self.R = np.asarray(self.R, float)
        self.T = np.asarray(self.T, float)
        shapes = {a.shape for a in (self.time_s, self.camera, self.led, self.R, self.T)}
        if len(shapes) != 1 or self.time_s.ndim != 1:
            raise ArgumentError(f"recording columns must be 1-D of equal length, got {shapes}")

    def __len__(self) -> int:
        return int(self.time_s.size)

    def fields(self, n_cameras: int = 2):
        """Group detections by field.

        Returns ``(times (F,) [s], leds (F,), pixels (n_cameras, F, 2) [pixel])`` with
        NaN pixels where a camera missed the LED of that field.
        """
        times, inverse = np.unique(self.time_s, return_inverse=True)
        leds = np.zeros(times.size, int)
        leds[inverse] = self.led
        pixels = np.full((n_cameras, times.size, 2), np.nan)
        if np.any((self.camera < 0) | (self.camera >= n_cameras)):
            raise ArgumentError(f"camera index outside 0..{n_cameras - 1}")
        pixels[self.camera, inverse, 0] = self.R
        pixels[self.camera, inverse, 1] = self.T
        return times, leds, pixels


def _float(path, lineno, text, name):
    try:
        value = float(text)
    except ValueError:
        raise RecordingError(path, lineno, text, f"{name} is not a number") from None
    if not math.isfinite(value):
        raise RecordingError(path, lineno, text, f"{name} is not a finite number")
    return value


def _int(path, lineno, text, name):
    try:
        return int(text)
    except ValueError:
        raise RecordingError(path, lineno, text, f"{name} is not an integer") from None


def parse_recording(lines, path="<recording>", n_cameras: int = 2) -> Recording:
    """Parse recording text given as an iterable of lines (see module docstring)."""
    t_list, c_list, l_list, r_list, tt_list = [], [], [], [], []
    header_seen = False
    last_time = -math.inf
    last_line = 0
    field_led: tuple[int, int] | None = None        # (led, line) of the current field
    field_cams: dict[int, int] = {}                  # camera -> line in the current field
    for lineno, raw in enumerate(lines, start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        parts = [p.strip() for p in line.split(",")]
        if not header_seen:
            if tuple(parts) != HEADER:
                raise RecordingError(path, lineno, line, f"expected header {','.join(HEADER)}")
            header_seen = True
            continue
        if len(parts) != len(HEADER):
            raise RecordingError(
                path, lineno, line, f"expected {len(HEADER)} fields ({','.join(HEADER)}), got {len(parts)}"
            )
        t = _float(path, lineno, parts[0], "time_s")
        cam = _int(path, lineno, parts[1], "camera")
        if not 0 <= cam < n_cameras:
            raise RecordingError(path, lineno, parts[1], f"unknown camera (expected 0..{n_cameras - 1})")
        led = _int(path, lineno, parts[2], "led")
        if not 1 <= led <= N_LEDS:
            raise RecordingError(path, lineno, parts[2], f"bad led number (expected 1..{N_LEDS})")
        R = _float(path, lineno, parts[3], "R")
        T = _float(path, lineno, parts[4], "T")
        if t < last_time:
            raise RecordingError(
                path, lineno, parts[0], f"time_s goes backwards (line {last_line} has {last_time!r} s)"
            )
        if t != last_time:
            field_led, field_cams = (led, lineno), {}
        else:
            assert field_led is not None
            if led != field_led[0]:
                raise RecordingError(
                    path, lineno, parts[2],
                    f"led differs from led {field_led[0]} on line {field_led[1]} in the same field "
                    f"(time_s {t!r}); one LED flashes per field",
                )
            if cam in field_cams:
                raise RecordingError(
                    path, lineno, parts[1],
                    f"camera appears twice in the field at time_s {t!r} (first on line {field_cams[cam]})",
                )
        field_cams[cam] = lineno
        last_time, last_line = t, lineno
        t_list.append(t)
        c_list.append(cam)
        l_list.append(led)
        r_list.append(R)
        tt_list.append(T)
    if not header_seen:
        raise RecordingError(path, 1, "", f"empty recording: no header {','.join(HEADER)}")
    return Recording(np.array(t_list, float), np.array(c_list, int), np.array(l_list, int),
                     np.array(r_list, float), np.array(tt_list, float))


def read_recording(path, n_cameras: int = 2) -> Recording:
    """Read a recording CSV file; raises :class:`RecordingError` on malformed content."""
    text = read_text(path, TeachError)
    return parse_recording(io.StringIO(text, newline=""), path=os.fspath(path), n_cameras=n_cameras)


def _format(value: float) -> str:
    """Shortest text that reads back to the same float; integers without '.0'."""
    if value == int(value) and abs(value) < 1e15:
        return str(int(value))
    return repr(float(value))


def format_recording(rec: Recording) -> str:
    """CSV text of a recording (header + one line per detection, file order)."""
    for name in ("time_s", "R", "T"):
        values = getattr(rec, name)
        bad = np.nonzero(~np.isfinite(values))[0]
        if bad.size:
            raise ArgumentError(f"cannot write detection {bad[0]}: {name}={float(values[bad[0]])!r} is not finite")
    out = [",".join(HEADER)]
    for t, c, l, R, T in zip(rec.time_s, rec.camera, rec.led, rec.R, rec.T):
        out.append(f"{repr(float(t))},{int(c)},{int(l)},{_format(R)},{_format(T)}")
    return "\n".join(out) + "\n"


def write_recording(path, rec: Recording, n_cameras: int = 2) -> None:
    """Write ``rec`` to ``path`` after checking it obeys the format rules."""
    text = format_recording(rec)
    parse_recording(text.splitlines(), path=os.fspath(path), n_cameras=n_cameras)  # validate
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text)
