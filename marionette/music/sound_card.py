"""The live music from a sound card: audio blocks in, one loudness frame per
tick out, to a sink (e.g. ``Engine.push_loudness``); a live source as
marionette.music.source declares it.

    from marionette.music.sound_card import SoundCard
    with SoundCard(engine.push_loudness, device="USB Audio") as source:
        engine.start()
        ...

The frames are the same feature as the stored loudness (marionette.music.feature:
band RMS of each 20 ms of audio, linear), so teach and show time agree;
the follower is insensitive to the volume and the sample rate. Capture runs
on the sound card's sample rate (its default, or the one asked for), mono
(channels averaged). PortAudio's thread calls ``_on_block`` with each block;
the frames it completes go to the sink in that thread, in order.

The sound card comes through the optional ``sounddevice`` package (the
``audio`` extra: ``pip install 'marionette[audio]'``). Without it, without
PortAudio, or without an input device, SoundCard raises AudioError
saying which and what to do.

While it runs, the source reports: the stream's input latency
(``latency`` [s]), a lost source (``on_lost(reason)`` once, ``lost_reason``)
with PortAudio's own stderr lines kept off the terminal and folded into the
reason, and counts of frames, overflows and refused frames (docs/music.md).
"""
from __future__ import annotations

import re
import threading
import time
from typing import Callable

import numpy as np

from marionette.music.bands import BandMeter
from marionette.music.feature import FRAME_PERIOD, AudioError, LoudnessMeter, OnsetMeter
from marionette.music.source import LiveSource, Sink
from marionette.music.stderr_catch import StderrCatcher

BLOCK_PERIOD = 0.010            # capture block [s]: half a frame, so frames leave on time
LOST_SILENCE = 0.5              # no block for this long while running: the source is lost [s]
# the first block may come late: PulseAudio's null-sink monitor took up to
# 2.0 s (ALSA pulse plugin, tests/hil/test_audio_hil.py); a sound card
# answers within a block or two
FIRST_BLOCK_WAIT = 5.0          # [s]
WATCH_PERIOD = 0.1              # the watchdog looks this often [s]
LINES_WAIT = 0.1                # after trouble, wait this long for PortAudio's stderr lines [s]


def import_sounddevice():
    """The sounddevice module, or AudioError when it (or PortAudio) is missing."""
    try:
        import sounddevice
    except ImportError:
        raise AudioError("live audio needs the 'sounddevice' package: "
                         "pip install 'marionette[audio]'") from None
    except OSError as exc:      # sounddevice is there, the PortAudio library is not
        raise AudioError(f"live audio needs the PortAudio library ({exc}); on Debian: "
                         "apt-get install libportaudio2") from None
    return sounddevice


def input_devices(sd=None) -> list[dict]:
    """The sound cards that can record: index, name, channels, default rate [Hz]."""
    sd = sd or import_sounddevice()
    try:
        devices = sd.query_devices()
    except Exception as exc:    # PortAudioError and the like: no audio system at all
        raise AudioError(f"cannot list audio devices: {exc}") from None
    return [{"index": i, "name": d["name"], "channels": int(d["max_input_channels"]),
             "sample_rate": float(d["default_samplerate"])}
            for i, d in enumerate(devices) if int(d["max_input_channels"]) > 0]


def _listing(devices: list[dict]) -> str:
    return ", ".join(f"{d['index']}: {d['name']}" for d in devices)


def _choose(devices: list[dict], device) -> dict:
    """The input named by device: None or "" (the first input), an index (an
    int, or a string of digits as a command line gives it), or a part of the
    name (case ignored; a name equal to it wins over names that contain it)."""
    if not devices:
        raise AudioError("no audio input device found (is a sound card or microphone connected?)")
    if device is None or (isinstance(device, str) and not device.strip()):
        return devices[0]
    if isinstance(device, str) and device.strip().isdigit():
        device = int(device.strip())
    if isinstance(device, bool) or not isinstance(device, (int, str)):
        raise AudioError(f"audio input {device!r}: give an index or a part of the name "
                         f"(inputs: {_listing(devices)})")
    if isinstance(device, int):
        for d in devices:
            if d["index"] == device:
                return d
        raise AudioError(f"no audio input device {device} (inputs: {_listing(devices)})")
    part = device.strip().lower()
    exact = [d for d in devices if d["name"].lower() == part]
    matches = exact or [d for d in devices if part in d["name"].lower()]
    if len(matches) == 1:
        return matches[0]
    if len(matches) > 1:
        raise AudioError(f"audio input {device!r} is ambiguous: {_listing(matches)} "
                         "(give the index)")
    raise AudioError(f"no audio input device {device!r} (inputs: {_listing(devices)})")


def _summarize(lines: list[str], most: int = 3) -> str:
    """PortAudio's failed-expression lines cut to the names of what failed."""
    items: list[str] = []
    for line in lines:
        m = re.match(r"Expression '([A-Za-z_]\w*)", line)
        item = f"{m.group(1)} failed" if m else line.strip()
        if item not in items:
            items.append(item)
    more = len(items) - most
    return "; ".join(items[:most]) + (f"; {more} more" if more > 0 else "")


class SoundCard(LiveSource):
    """A sound card as a live source (marionette.music.source).

    sink(value) gets each frame (linear loudness >= 0, one per period
    [s] of audio); with onsets=True sink(value, onset), the frame's
    onset strength [dB] beside it (``Engine.push_loudness`` takes both);
    with bands=True also the frame's band levels (marionette.music.bands),
    sink(value, onset, bands) (onset NaN without onsets=True).
    device: index (int or digit string) or part of the name (None: the
    first input); sample_rate [Hz] (None: the device's default); channels
    to record (averaged to mono). sd: the sounddevice module to use (tests).

    on_lost(reason) is called once, from a watchdog thread (or from stop()),
    when the source is lost: the stream ended or failed by itself, or no
    audio came for LOST_SILENCE while it ran (FIRST_BLOCK_WAIT before the
    first block). ``lost_reason`` keeps the reason (None while all is well).
    With catch_stderr, what PortAudio and ALSA print on stderr while the
    stream is open is kept off the terminal (marionette.music.stderr_catch) and
    folded into the reason; ``messages`` has the lines.

    Reported: ``frames`` delivered, ``overflows`` (blocks PortAudio flagged
    as an input overflow: audio was dropped before it reached us),
    ``underflows`` (blocks flagged as input underflow), ``refused`` (frames
    the sink raised on; ``refused_error`` the newest such error),
    ``latency`` [s] (the stream's input latency, once started).
    """

    def __init__(self, sink: Sink | None, device=None,
                 sample_rate: float | None = None, channels: int = 1,
                 period: float = FRAME_PERIOD, sd=None, onsets: bool = False,
                 on_lost: Callable[[str], object] | None = None, catch_stderr: bool = True,
                 bands: bool = False):
        super().__init__(sink, on_lost)
        self.sd = sd or import_sounddevice()
        self.catch_stderr = catch_stderr
        self.device = _choose(input_devices(self.sd), device)
        self.sample_rate = float(sample_rate or self.device["sample_rate"])          # [Hz]
        if not 1 <= channels <= max(1, self.device["channels"]):
            raise AudioError(f"audio input {self.device['name']!r} has {self.device['channels']} "
                             f"channel(s), {channels} asked for")
        self.channels = int(channels)
        try:
            self.sd.check_input_settings(device=self.device["index"], channels=self.channels,
                                         samplerate=self.sample_rate)
        except Exception as exc:
            raise AudioError(f"audio input {self.device['name']!r} cannot record {self.channels} "
                             f"channel(s) at {self.sample_rate:g} Hz: {exc}") from None
        self.meter = LoudnessMeter(self.sample_rate, period)       # AudioError below 8 kHz
        self.onset_meter = OnsetMeter(self.sample_rate, period) if onsets else None
        self.band_meter = BandMeter(self.sample_rate, period) if bands else None
        self.overflows = 0              # blocks flagged input overflow
        self.underflows = 0             # blocks flagged input underflow
        self.refused = 0                # frames the sink raised on
        self.refused_error: str | None = None
        self.messages: list[str] = []   # PortAudio / ALSA lines caught off stderr
        self._latency: float | None = None                   # [s]
        self._lock = threading.Lock()
        self._lost_lock = threading.Lock()
        self._stream = None
        self._watchdog: threading.Thread | None = None
        self._wake = threading.Event()          # the watchdog looks now
        self._stopping = threading.Event()      # stop() has begun: an ending stream is ours
        self._trouble: str | None = None        # what PortAudio's thread saw go wrong
        self._started_at = 0.0                  # [s] time.monotonic()
        self._last_block: float | None = None   # newest block's arrival [s] time.monotonic()

    @property
    def name(self) -> str:
        return self.device["name"]

    @property
    def latency(self) -> float | None:
        """The stream's input latency [s] as PortAudio reports it: how long
        before a block reaches us its newest sample came in (None before
        start()). A frame is complete with the block that ends it, so this
        is the age of the newest frame's audio end when the frame is handed
        to the sink: the default for the [follow] latency."""
        return self._latency

    # --- PortAudio's thread --------------------------------------------------------------

    def _on_block(self, indata, frames, time_info, status) -> None:
        """PortAudio's callback: one block of audio, shape (frames, channels)."""
        self._last_block = time.monotonic()
        if status:
            if getattr(status, "input_overflow", True):
                self.overflows += 1
            if getattr(status, "input_underflow", False):
                self.underflows += 1
        try:
            block = np.asarray(indata, dtype=np.float64).reshape(frames, -1)
            with self._lock:
                values = self.meter.feed(block)
                onsets = None if self.onset_meter is None else self.onset_meter.feed(block)
                rows = None if self.band_meter is None else self.band_meter.feed(block)
        except Exception as exc:        # never into PortAudio, which would print it
            self._trouble = f"a block could not be measured: {type(exc).__name__}: {exc}"
            self._wake.set()
            return
        for i, v in enumerate(values):
            if self.sink is None:       # no sink yet: dropped
                continue
            try:
                if rows is not None:
                    self.sink(float(v), float("nan") if onsets is None else float(onsets[i]),
                              rows[i] if i < len(rows) else None)
                elif onsets is None:
                    self.sink(float(v))
                else:
                    self.sink(float(v), float(onsets[i]))
            except Exception as exc:    # the consumer's trouble, not the source's
                self.refused += 1
                self.refused_error = f"{type(exc).__name__}: {exc}"
                continue
            self.frames += 1

    def _on_finished(self) -> None:
        """PortAudio: the stream has become inactive (our stop(), or it died)."""
        if not self._stopping.is_set():
            self._trouble = self._trouble or "the stream ended by itself"
            self._wake.set()

    def _on_library_line(self, line: str) -> None:
        self.messages.append(line)

    # --- the watchdog --------------------------------------------------------------------

    def _check(self) -> str | None:
        """Why the source is lost, or None."""
        if self._trouble:
            return self._trouble
        now, last, stream = time.monotonic(), self._last_block, self._stream
        if last is None:
            if now - self._started_at > FIRST_BLOCK_WAIT:
                return f"no audio in the first {FIRST_BLOCK_WAIT:g} s"
        elif now - last > LOST_SILENCE:
            return f"no audio for {now - last:.1f} s"
        if stream is not None:
            try:
                active = getattr(stream, "active", True)
            except Exception as exc:
                return f"the stream failed: {exc}"
            if not active and not self._stopping.is_set():
                return "the stream ended by itself"
        return None

    def _watch(self) -> None:
        while True:
            self._wake.wait(WATCH_PERIOD)
            self._wake.clear()
            if self._stopping.is_set():
                return
            reason = self._check()
            if reason is not None:
                # PortAudio prints as it fails: give the relay a moment to hand the lines over
                time.sleep(LINES_WAIT)
                self._lose(reason)
                return

    def _lose(self, reason: str) -> None:
        with self._lost_lock:
            if self.lost_reason is not None:
                return
            if self.messages:
                reason += f" (PortAudio: {_summarize(self.messages)})"
            self.lost_reason = reason
        if self.on_lost is not None:
            self.on_lost(reason)

    # --- start and stop ------------------------------------------------------------------

    def start(self) -> "SoundCard":
        if self._stream is not None:
            return self
        self._stopping.clear()
        self._wake.clear()
        self._trouble = self._last_block = None
        catcher = StderrCatcher.shared() if self.catch_stderr else None
        if catcher is not None:
            catcher.add(self._on_library_line)
        self._started_at = time.monotonic()
        try:
            self._stream = self.sd.InputStream(
                device=self.device["index"], channels=self.channels, samplerate=self.sample_rate,
                blocksize=max(1, int(round(self.sample_rate * BLOCK_PERIOD))),
                dtype="float32", callback=self._on_block, finished_callback=self._on_finished)
            self._stream.start()
        except Exception as exc:
            stream, self._stream = self._stream, None
            if stream is not None:
                _quietly(stream.close)
            if catcher is not None:
                catcher.remove(self._on_library_line)
            said = f" (PortAudio: {_summarize(self.messages)})" if self.messages else ""
            raise AudioError(f"cannot record from {self.name!r}: {exc}{said}") from None
        latency = getattr(self._stream, "latency", None)
        self._latency = float(latency) if isinstance(latency, (int, float)) else None
        self._watchdog = threading.Thread(target=self._watch, name="audio-watchdog", daemon=True)
        self._watchdog.start()
        return self

    def stop(self) -> None:
        if self._stream is None:
            return
        self._stopping.set()
        self._wake.set()
        if self._watchdog is not None and self._watchdog is not threading.current_thread():
            self._watchdog.join()
        stream, self._stream = self._stream, None
        stop_failed, close_failed = _quietly(stream.stop), _quietly(stream.close)
        failed = stop_failed or close_failed
        if self._trouble is not None:           # it died after the watchdog's last look
            self._lose(self._trouble)
        elif failed is not None:
            self._lose(f"stopping the stream failed: {failed}")
        if self.catch_stderr:
            StderrCatcher.shared().remove(self._on_library_line)


def _quietly(action) -> str | None:
    """Run action(); the error's text if it raised."""
    try:
        action()
    except Exception as exc:
        return f"{type(exc).__name__}: {exc}"
    return None
