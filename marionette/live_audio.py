"""Live loudness from a sound card: audio blocks in, one loudness frame per
tick out, to a callback (e.g. ``Engine.push_loudness``).

    from marionette.live_audio import LiveLoudness
    with LiveLoudness(engine.push_loudness, device="USB Audio") as source:
        engine.start()
        ...

The frames are the same feature as the stored loudness (marionette.loudness:
band RMS of each 20 ms of audio, linear), so teach and show time agree;
the follower is insensitive to the volume and the sample rate. Capture runs
on the sound card's sample rate (its default, or the one asked for), mono
(channels averaged). PortAudio's thread calls ``_on_block`` with each block;
the frames it completes go to the callback in that thread, in order.

The sound card comes through the optional ``sounddevice`` package (the
``audio`` extra: ``pip install 'marionette[audio]'``). Without it, without
PortAudio, or without an input device, LiveLoudness raises AudioError
saying which and what to do.
"""
from __future__ import annotations

import threading
from typing import Callable

import numpy as np

from marionette.loudness import FRAME_PERIOD, AudioError, LoudnessMeter, OnsetMeter

BLOCK_PERIOD = 0.010            # capture block [s]: half a frame, so frames leave on time


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


def _choose(devices: list[dict], device) -> dict:
    if not devices:
        raise AudioError("no audio input device found (is a sound card or microphone connected?)")
    if device is None:
        return devices[0]
    if isinstance(device, int) and not isinstance(device, bool):
        for d in devices:
            if d["index"] == device:
                return d
    elif isinstance(device, str):
        matches = [d for d in devices if device.lower() in d["name"].lower()]
        if len(matches) == 1:
            return matches[0]
        if len(matches) > 1:
            raise AudioError(f"audio input {device!r} is ambiguous: "
                             + ", ".join(f"{d['index']}: {d['name']}" for d in matches))
    known = ", ".join(f"{d['index']}: {d['name']}" for d in devices)
    raise AudioError(f"no audio input device {device!r} (inputs: {known})")


class LiveLoudness:
    """A sound card as a source of loudness frames.

    callback(value) gets each frame (linear loudness >= 0, one per period
    [s] of audio); with onsets=True callback(value, onset), the frame's
    onset strength [dB] beside it (``Engine.push_loudness`` takes both).
    device: index or part of the name (None: the first input); sample_rate
    [Hz] (None: the device's default); channels to record (averaged to
    mono). sd: the sounddevice module to use (tests).
    """

    def __init__(self, callback: Callable[..., object], device=None,
                 sample_rate: float | None = None, channels: int = 1,
                 period: float = FRAME_PERIOD, sd=None, onsets: bool = False):
        self.sd = sd or import_sounddevice()
        self.callback = callback
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
        self.frames = 0                 # frames delivered
        self.overflows = 0              # blocks PortAudio reported as overflowed or dropped
        self._lock = threading.Lock()
        self._stream = None

    def _on_block(self, indata, frames, time_info, status) -> None:
        """PortAudio's callback: one block of audio, shape (frames, channels)."""
        if status:
            self.overflows += 1
        block = np.asarray(indata, dtype=np.float64).reshape(frames, -1)
        with self._lock:
            values = self.meter.feed(block)
            onsets = None if self.onset_meter is None else self.onset_meter.feed(block)
        for i, v in enumerate(values):
            if onsets is None:
                self.callback(float(v))
            else:
                self.callback(float(v), float(onsets[i]))
            self.frames += 1

    def start(self) -> "LiveLoudness":
        if self._stream is None:
            try:
                self._stream = self.sd.InputStream(
                    device=self.device["index"], channels=self.channels, samplerate=self.sample_rate,
                    blocksize=max(1, int(round(self.sample_rate * BLOCK_PERIOD))),
                    dtype="float32", callback=self._on_block)
                self._stream.start()
            except Exception as exc:
                self._stream = None
                raise AudioError(f"cannot record from {self.device['name']!r}: {exc}") from None
        return self

    def stop(self) -> None:
        if self._stream is not None:
            stream, self._stream = self._stream, None
            stream.stop()
            stream.close()

    def __enter__(self) -> "LiveLoudness":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
