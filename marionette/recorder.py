"""Flight recorder: every tick's record (tick, time, playback position and
rate, loudness, flags, every command), drained from the engine's ring by
Python into memory or a file.

File format (docs/formats.md): one ASCII header line
``MARIONETTE-FLIGHT 1 <json>`` then the raw little-endian records, each laid
out as ``marionette._core.record_dtype(n_axes)``.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from marionette.errors import ArgumentError, MarionetteError

MAGIC = b"MARIONETTE-FLIGHT 1 "


class FlightRecorder:
    """Keeps drained records in memory, or appends them to a file when given a path."""

    def __init__(self, dtype: np.dtype, axis_names: list[str], path: str | Path | None = None,
                 meta: dict | None = None):
        self.dtype = dtype
        self.path = Path(path) if path is not None else None
        self.count = 0                     # records kept [ticks]
        self._chunks: list[np.ndarray] = []
        self._file = None
        self.error: str | None = None      # why the file could not be written (then kept no more)
        # called with each batch of records as it is added (on the drain thread)
        self.listeners: list = []
        if self.path is not None:
            header = dict(meta or {}, axis_names=list(axis_names),
                          record_bytes=dtype.itemsize)
            self._file = open(self.path, "wb")
            self._file.write(MAGIC + json.dumps(header).encode() + b"\n")

    def add(self, records: np.ndarray) -> None:
        if not len(records):
            return
        self.count += len(records)
        for listen in self.listeners:
            listen(records)
        if self.path is None:
            self._chunks.append(records.copy())
        elif self._file is not None:
            try:
                self._file.write(records.tobytes())
            except OSError as exc:         # a full disk: said when the records are asked for
                self._failed(exc)

    def records(self) -> np.ndarray:
        """All records so far (from memory, or re-read from the file)."""
        if self.path is not None:
            if self._file is not None:
                try:
                    self._file.flush()
                except OSError as exc:
                    self._failed(exc)
            if self.error is not None:
                raise MarionetteError(self.error)
            return read_flight_record(self.path)[1]
        if not self._chunks:
            return np.empty(0, dtype=self.dtype)
        return np.concatenate(self._chunks)

    def close(self) -> None:
        if self._file is not None:
            try:
                self._file.close()
            except OSError as exc:
                self._failed(exc)
            self._file = None

    def _failed(self, exc: OSError) -> None:
        if self.error is None:
            self.error = f"{self.path}: cannot write the flight record: {exc.strerror or exc}"
        try:
            self._file.close()
        except (OSError, AttributeError):
            pass
        self._file = None

    def __del__(self):
        self.close()


def read_flight_record(path: str | Path) -> tuple[dict, np.ndarray]:
    """(header dict, structured array of records) of a flight-record file."""
    from marionette._core import record_dtype
    with open(path, "rb") as f:
        line = f.readline()
        if not line.startswith(MAGIC):
            raise ArgumentError(f"{path}: not a marionette flight record (bad first line)")
        meta = json.loads(line[len(MAGIC):])
        dtype = record_dtype(len(meta["axis_names"]))
        raw = f.read()
    if len(raw) % dtype.itemsize:
        raise ArgumentError(f"{path}: {len(raw)} bytes of records is not a whole number of "
                            f"{dtype.itemsize}-byte records (file cut short?)")
    return meta, np.frombuffer(raw, dtype=dtype)
