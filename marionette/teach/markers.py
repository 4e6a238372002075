"""CSV of calibration markers: known object points and where each camera sees them.

Format
------
UTF-8 text, comma separated, with this header line::

    camera,marker,x,y,z,R,T

* ``camera`` - camera index, an integer ``0 .. n-1`` (every index up to the highest
  must have markers);
* ``marker`` - the marker's name (any text without a comma; used in messages);
* ``x, y, z`` - the marker's position in object space [m] (z up, the frame the
  teach-in works in); a marker seen by several cameras repeats its position on each
  line, and the positions must agree;
* ``R`` - pixel column [pixel], ``T`` - pixel row counted *upwards* [pixel] (as in
  :mod:`marionette.teach.camera`).

One line per marker per camera; a camera lists each marker at most once.  Blank lines
and lines starting with ``#`` are ignored.  Errors raise :class:`MarkerError` (a
``ValueError``) naming the file, the line (1-based) and the offending value.
"""

from __future__ import annotations

import io
import math
import os
from dataclasses import dataclass

import numpy as np

from marionette.errors import ArgumentError, LineError, TeachError
from marionette.textfile import read_text

HEADER = ("camera", "marker", "x", "y", "z", "R", "T")


class MarkerError(LineError):
    """Malformed marker file."""


@dataclass
class CameraMarkers:
    """The markers one camera sees."""

    names: list[str]          # marker names, file order
    points: np.ndarray        # (n, 3) object coordinates [m]
    pixels: np.ndarray        # (n, 2) (R, T) [pixel]
    lines: list[int]          # line of each marker in the file


def _float(path, lineno, text, name):
    try:
        value = float(text)
    except ValueError:
        raise MarkerError(path, lineno, text, f"{name} is not a number") from None
    if not math.isfinite(value):
        raise MarkerError(path, lineno, text, f"{name} is not a finite number")
    return value


def parse_markers(lines, path="<markers>") -> list[CameraMarkers]:
    """Parse marker text (an iterable of lines); returns one entry per camera 0..n-1."""
    per_camera: dict[int, CameraMarkers] = {}
    positions: dict[str, tuple[tuple[float, float, float], int]] = {}
    header_seen = False
    for lineno, raw in enumerate(lines, start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        parts = [p.strip() for p in line.split(",")]
        if not header_seen:
            if tuple(parts) != HEADER:
                raise MarkerError(path, lineno, line, f"expected header {','.join(HEADER)}")
            header_seen = True
            continue
        if len(parts) != len(HEADER):
            raise MarkerError(path, lineno, line,
                              f"expected {len(HEADER)} fields ({','.join(HEADER)}), got {len(parts)}")
        try:
            cam = int(parts[0])
        except ValueError:
            raise MarkerError(path, lineno, parts[0], "camera is not an integer") from None
        if cam < 0:
            raise MarkerError(path, lineno, parts[0], "camera index must be >= 0")
        name = parts[1]
        if not name:
            raise MarkerError(path, lineno, parts[1], "marker name is empty")
        xyz = tuple(_float(path, lineno, parts[i], HEADER[i]) for i in (2, 3, 4))
        R = _float(path, lineno, parts[5], "R")
        T = _float(path, lineno, parts[6], "T")
        if name in positions and positions[name][0] != xyz:
            first, first_line = positions[name]
            raise MarkerError(path, lineno, ",".join(parts[2:5]),
                              f"marker {name!r} is at {list(first)} m on line {first_line}; "
                              "a marker has one position")
        positions.setdefault(name, (xyz, lineno))
        entry = per_camera.setdefault(cam, CameraMarkers([], np.zeros((0, 3)), np.zeros((0, 2)), []))
        if name in entry.names:
            raise MarkerError(path, lineno, name,
                              f"camera {cam} lists marker {name!r} twice "
                              f"(first on line {entry.lines[entry.names.index(name)]})")
        entry.names.append(name)
        entry.points = np.vstack([entry.points, xyz])
        entry.pixels = np.vstack([entry.pixels, (R, T)])
        entry.lines.append(lineno)
    if not header_seen:
        raise MarkerError(path, 1, "", f"empty marker file: no header {','.join(HEADER)}")
    if not per_camera:
        raise MarkerError(path, lineno if header_seen else 1, "", "no markers after the header")
    n = max(per_camera) + 1
    missing = [k for k in range(n) if k not in per_camera]
    if missing:
        raise ArgumentError(f"{path}: camera {missing[0]} has no markers "
                            f"(cameras are numbered 0..{n - 1} without gaps)")
    return [per_camera[k] for k in range(n)]


def read_markers(path) -> list[CameraMarkers]:
    """Read a marker file; raises :class:`MarkerError` on malformed content."""
    text = read_text(path, TeachError)
    return parse_markers(io.StringIO(text, newline=""), path=os.fspath(path))


def _format(value: float) -> str:
    return repr(round(float(value), 6))


def format_markers(cameras: list[CameraMarkers]) -> str:
    """CSV text of the markers of every camera (camera by camera)."""
    out = [",".join(HEADER)]
    for k, cm in enumerate(cameras):
        for name, X, pix in zip(cm.names, cm.points, cm.pixels):
            out.append(",".join([str(k), name, *(_format(v) for v in X), *(_format(v) for v in pix)]))
    return "\n".join(out) + "\n"


def write_markers(path, cameras: list[CameraMarkers], comment: str = "") -> None:
    """Write a marker file (optional ``# comment`` lines first) and check it reads back."""
    text = "".join(f"# {c}\n" for c in comment.splitlines()) + format_markers(cameras)
    parse_markers(text.splitlines(), path=os.fspath(path))
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text)
