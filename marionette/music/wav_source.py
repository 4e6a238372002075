"""A recording played back as if it were the live music (``play --music``):
a live source as marionette.music.source declares it.

The frames (loudness and onset strength, marionette.music.feature, and with
bands=True the band levels, marionette.music.bands) are measured from the
whole file when the source is made. In real time,
start() hands the sink one frame per period from a thread, as a sound card
would; in step mode the caller hands them over tick by tick (feed_tick),
the way the engine hears them: tick k has heard the music up to k * period,
so it gets frame k - 1 (follower.sync_ticks).
"""
from __future__ import annotations

import threading
import time

import numpy as np

from marionette.music.bands import wav_music_frames
from marionette.music.feature import FRAME_PERIOD, wav_frames
from marionette.music.follower import sync_ticks
from marionette.music.source import LiveSource, Sink


class WavSource(LiveSource):
    """The recording at path as a live source, one frame per period [s].

    ``loudness`` [full scale] and ``onsets`` [dB]: its frames, one per period;
    ``bands`` (frames, N_BANDS) [full scale] with bands=True, else None: the
    sink then gets sink(loudness, onset, bands). The latency is None (a
    recording has no input latency)."""

    def __init__(self, path, sink: Sink | None = None, period: float = FRAME_PERIOD, on_lost=None,
                 bands: bool = False):
        super().__init__(sink, on_lost)
        self.path = path
        self.period = float(period)                             # [s]
        if bands:           # [full scale], [dB], [full scale]
            self.loudness, self.onsets, self.bands = wav_music_frames(path, period)
        else:
            (self.loudness, self.onsets), self.bands = wav_frames(path, period), None
        self._by_tick = (sync_ticks(self.loudness), sync_ticks(self.onsets),
                         None if self.bands is None else sync_ticks(self.bands))   # tick k: frame k - 1
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def name(self) -> str:
        return str(self.path)

    def feed_tick(self, k: int) -> None:
        """Step mode: hand the sink the frame tick k [ticks] has heard, if any."""
        loud, onset, rows = self._by_tick
        if k < len(loud) and not np.isnan(loud[k]) and self.sink is not None:
            self._deliver(loud[k], onset[k], None if rows is None else rows[k])

    def start(self) -> "WavSource":
        """Real time: one frame per period from a thread, from now on."""
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._play, name="wav-source", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join()
        self._thread = None

    def _play(self) -> None:
        start = time.monotonic()                                # [s]
        for k, (value, onset) in enumerate(zip(self.loudness, self.onsets)):
            if self._stop.wait(max(0.0, start + (k + 1) * self.period - time.monotonic())):
                return
            if self.sink is not None:
                self._deliver(value, onset, None if self.bands is None else self.bands[k])

    def _deliver(self, value, onset, bands) -> None:
        if bands is None:
            self.sink(float(value), float(onset))
        else:
            self.sink(float(value), float(onset), bands)
        self.frames += 1
