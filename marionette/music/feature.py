"""The music's loudness, one value per 20 ms tick: the feature the engine
correlates at the show against the one stored at teach time; and beside it
the onset strength (OnsetMeter), whose lag the tracker measures as well.

The same code computes it at both times, so the two agree by construction:

* band-limited RMS: the power between 60 Hz and 4 kHz of each 20 ms frame
  (rectangular window, from the FFT of the frame). The band makes the feature
  the same at any sample rate from 8 kHz up, and ignores hum and rumble;
* returned linear (full scale = 1.0 for a full-scale sine in the band). The
  volume knob multiplies every value by one factor, which the follower
  removes by working on the logarithm with the mean taken out.

Frame k covers the samples [floor(k * fs * T), floor(k * fs * T) + floor(fs * T))
of a recording at fs [Hz] with period T [s]: the music from k * T on.
"""
from __future__ import annotations

import struct
import wave
from pathlib import Path

import numpy as np

from marionette.errors import MarionetteError

FRAME_PERIOD = 0.020        # [s], one engine tick
BAND = (60.0, 4000.0)       # [Hz] band whose power is measured


class AudioError(MarionetteError):
    """An audio file or device could not be read."""


class LoudnessMeter:
    """Turns a stream of audio blocks into loudness frames.

    feed() accepts blocks of any length (mono, or (samples, channels)) and
    returns the frames they completed; the remainder waits for the next block.
    """

    def __init__(self, sample_rate: float, period: float = FRAME_PERIOD):
        if not (sample_rate >= 2 * BAND[1]):
            raise AudioError(f"sample rate {sample_rate!r} Hz is below {2 * BAND[1]:g} Hz")
        self.sample_rate = float(sample_rate)                   # [Hz]
        self.period = float(period)                             # [s]
        self.frame_len = int(np.floor(sample_rate * period))    # [samples]
        freqs = np.fft.rfftfreq(self.frame_len, 1.0 / sample_rate)
        self._band = (freqs >= BAND[0]) & (freqs <= BAND[1])
        self._pending = np.zeros(0)                             # samples not yet framed
        self._frames = 0                                        # frames emitted
        self._consumed = 0                                      # [samples] dropped before _pending

    def feed(self, block) -> np.ndarray:
        x = mono(block)
        self._pending = np.concatenate([self._pending, x])
        starts = []
        k = self._frames
        while True:
            start = int(np.floor(k * self.sample_rate * self.period)) - self._consumed
            if start + self.frame_len > len(self._pending):
                break
            starts.append(start)
            k += 1
        if not starts:
            return np.zeros(0)
        idx = np.asarray(starts)[:, None] + np.arange(self.frame_len)[None, :]
        frames = self._pending[idx]
        self._frames = k
        keep = int(np.floor(k * self.sample_rate * self.period)) - self._consumed
        self._pending = self._pending[keep:]
        self._consumed += keep
        return self.measure(frames)

    def measure(self, frames) -> np.ndarray:
        """The value of each frame (rows of frame_len samples, in order): here its loudness."""
        return self.frame_loudness(frames)

    def frame_loudness(self, frames) -> np.ndarray:
        """Loudness of frames (rows of frame_len samples) [full scale]."""
        spectrum = np.fft.rfft(np.atleast_2d(frames), axis=1)
        # Parseval: mean square of the band = 2 * sum |X|^2 / N^2 (one-sided spectrum)
        power = 2.0 * np.sum(np.abs(spectrum[:, self._band]) ** 2, axis=1) / self.frame_len ** 2
        return np.sqrt(power * 2.0)      # full-scale sine (mean square 1/2) -> 1.0


ONSET_EDGES = np.geomspace(60.0, 4000.0, 17)   # [Hz] edges of the 16 onset bands
ONSET_RANGE_DB = 50.0       # band powers this far under the frame's running peak read as that [dB]
ONSET_RELEASE_DB = 0.1      # ... the running peak falls this much per frame [dB]
ONSET_SMOOTH = 0.2          # band power smoothing for the noise estimate, per frame [1]
ONSET_RISE_DB = 0.05        # the band noise estimate rises at most this much per frame [dB]
ONSET_OVER_NOISE = 10.0     # band powers read as at least this times the band's noise estimate [1]
ONSET_SILENCE = 1e-14       # ... and never under this (digital silence) [full scale^2 per band]
ONSET_MAX_RISE_DB = 30.0    # a band's rise counts up to this much [dB]


class OnsetMeter(LoudnessMeter):
    """Turns a stream of audio blocks into onset strength frames [dB]: how
    much the music's band levels rose since the frame before.

    The same framing as LoudnessMeter (feed() returns one value per 20 ms
    frame); per frame, the power in 16 bands between 60 Hz and 4 kHz (Hann
    window), each read in dB over a floor, and the mean over the bands of
    the rise since the last frame (falls count 0, a rise at most 30 dB).
    A room colours each note by its own gain, which the loudness carries
    for as long as the note sounds; a rise in dB does not carry it. The
    floor is the highest of 50 dB under the running peak, a floor for
    digital silence and ten times the band's noise estimate (a minimum of
    the smoothed band power that rises 2.5 dB/s at most), so tape hiss in a
    quiet band does not read as onsets, nor a note after digital silence as
    a rise without bound. A volume knob scales every band alike and leaves
    the rises as they are.
    """

    def __init__(self, sample_rate: float, period: float = FRAME_PERIOD):
        super().__init__(sample_rate, period)
        freqs = np.fft.rfftfreq(self.frame_len, 1.0 / self.sample_rate)
        band = np.searchsorted(ONSET_EDGES, freqs, side="right") - 1           # band of each bin
        inside = (freqs >= ONSET_EDGES[0]) & (freqs < ONSET_EDGES[-1])
        self._bins = [np.flatnonzero(inside & (band == b)) for b in range(len(ONSET_EDGES) - 1)]
        self._window = np.hanning(self.frame_len)
        self._peak = None           # running peak of the frame's band power [dB]
        self._smooth = None         # smoothed band powers [full scale^2]
        self._noise = None          # band noise estimates [full scale^2]
        self._prev = None           # band levels of the last frame [dB]

    def measure(self, frames) -> np.ndarray:
        """Onset strength of consecutive frames (rows of frame_len samples) [dB]."""
        spectrum = np.abs(np.fft.rfft(np.atleast_2d(frames) * self._window, axis=1) / self.frame_len) ** 2
        bands = np.stack([spectrum[:, idx].sum(axis=1) for idx in self._bins], axis=1)
        total_db = 10.0 * np.log10(bands.sum(axis=1) + 1e-20)
        rise = 10.0 ** (ONSET_RISE_DB / 10.0)
        out = np.zeros(len(bands))
        for i, power in enumerate(bands):
            if self._peak is None:
                self._peak, self._smooth, self._noise = total_db[i], power.copy(), power.copy()
            self._peak = max(total_db[i], self._peak - ONSET_RELEASE_DB)
            self._smooth += ONSET_SMOOTH * (power - self._smooth)
            self._noise = np.minimum(self._smooth, self._noise * rise)
            floor = np.maximum(max(10.0 ** ((self._peak - ONSET_RANGE_DB) / 10.0), ONSET_SILENCE),
                               ONSET_OVER_NOISE * self._noise)
            level = 10.0 * np.log10(power + floor)
            if self._prev is not None:
                out[i] = np.mean(np.clip(level - self._prev, 0.0, ONSET_MAX_RISE_DB))
            self._prev = level
        return out


def onsets(samples, sample_rate: float, period: float = FRAME_PERIOD) -> np.ndarray:
    """Onset strength frames of a whole recording [dB], one per period."""
    return OnsetMeter(sample_rate, period).feed(samples)


def mono(samples) -> np.ndarray:
    """Samples (n,) or (n, channels) as one channel, the mean of them [full scale]."""
    x = np.asarray(samples, dtype=np.float64)
    return x.mean(axis=1) if x.ndim == 2 else x


def loudness(samples, sample_rate: float, period: float = FRAME_PERIOD) -> np.ndarray:
    """Loudness frames of a whole recording [full scale], one per period."""
    return LoudnessMeter(sample_rate, period).feed(samples)


WAVE_PCM, WAVE_FLOAT, WAVE_EXTENSIBLE = 0x0001, 0x0003, 0xFFFE    # WAVE format tags


def read_wav(path) -> tuple[np.ndarray, float]:
    """Samples scaled to [-1, 1] (shape (n,) or (n, channels)) and the sample rate [Hz].

    Integer PCM (8, 16, 24, 32 bit) and float WAV, plain or WAVE_FORMAT_EXTENSIBLE
    (as most 24-bit recorders write), read here; a file cut short gives the
    whole frames it holds. Any other format through the optional `soundfile`
    package when it is installed."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise AudioError(f"{path}: no such audio file") from None
    except OSError as exc:
        raise AudioError(f"{path}: cannot read it: {exc.strerror}") from None
    if not data:
        raise AudioError(f"{path}: empty file, not a WAV file")
    if data[:4] != b"RIFF" or data[8:12] != b"WAVE":
        return _read_with_soundfile(path, "it does not begin with RIFF....WAVE")
    fmt, samples = _wav_chunks(path, data)
    tag, channels, rate, _, align, bits = struct.unpack_from("<HHIIHH", fmt)
    if tag == WAVE_EXTENSIBLE:
        if len(fmt) < 26:
            raise AudioError(f"{path}: WAVE_FORMAT_EXTENSIBLE with a {len(fmt)}-byte fmt chunk, "
                             "too short for its sub-format")
        tag = struct.unpack_from("<H", fmt, 24)[0]          # the sub-format GUID's first field
    if tag not in (WAVE_PCM, WAVE_FLOAT):
        return _read_with_soundfile(path, f"WAVE format 0x{tag:04x}, neither integer PCM nor float")
    width = align // channels if channels else 0             # container bytes per sample
    if channels == 0 or rate == 0 or width == 0 or align != width * channels:
        raise AudioError(f"{path}: a fmt chunk with {channels} channels, {rate} Hz, "
                         f"{align} bytes per frame")
    raw = samples[:len(samples) - len(samples) % align]        # whole frames (a file cut short)
    if tag == WAVE_FLOAT:
        if width not in (4, 8):
            raise AudioError(f"{path}: {8 * width}-bit float samples are not supported")
        x = np.frombuffer(raw, f"<f{width}").astype(np.float64)
    elif width == 1:
        x = (np.frombuffer(raw, np.uint8).astype(np.float64) - 128.0) / 128.0
    elif width == 3:
        b = np.frombuffer(raw, np.uint8).reshape(-1, 3).astype(np.int32)
        v = b[:, 0] | (b[:, 1] << 8) | (b[:, 2] << 16)
        x = np.where(v >= 1 << 23, v - (1 << 24), v) / float(1 << 23)
    elif width in (2, 4):
        x = np.frombuffer(raw, f"<i{width}").astype(np.float64) / float(1 << (8 * width - 1))
    else:
        raise AudioError(f"{path}: {8 * width}-bit samples ({bits} bits used) are not supported")
    if channels > 1:
        x = x.reshape(-1, channels)
    return x, float(rate)


def _wav_chunks(path: Path, data: bytes) -> tuple[bytes, bytes]:
    """The fmt and data chunks of a RIFF WAVE file (data as far as the file goes)."""
    fmt = samples = None
    at = 12
    while at + 8 <= len(data) and (fmt is None or samples is None):
        name, size = data[at:at + 4], struct.unpack_from("<I", data, at + 4)[0]
        body = data[at + 8:at + 8 + size]
        if name == b"fmt ":
            fmt = body
        elif name == b"data":
            samples = body
        at += 8 + size + (size & 1)                          # chunks are padded to even sizes
    if fmt is None or len(fmt) < 16:
        raise AudioError(f"{path}: a WAV file without a whole fmt chunk (damaged or cut short)")
    if samples is None:
        raise AudioError(f"{path}: a WAV file without a data chunk (damaged or cut short)")
    return fmt, samples


def _read_with_soundfile(path: Path, cause: str):
    try:
        import soundfile
    except ImportError:
        raise AudioError(f"{path}: not a WAV file this reads ({cause}); install the 'audio' "
                         "extra (soundfile) to read other formats") from None
    try:
        x, rate = soundfile.read(str(path), dtype="float64", always_2d=False)
    except Exception as exc:
        raise AudioError(f"{path}: cannot read audio: {exc}") from None
    return x, float(rate)


def wav_loudness(path, period: float = FRAME_PERIOD) -> np.ndarray:
    """Loudness frames of an audio file [full scale], one per period."""
    return wav_frames(path, period)[0]


def wav_frames(path, period: float = FRAME_PERIOD) -> tuple[np.ndarray, np.ndarray]:
    """Loudness [full scale] and onset strength [dB] frames of an audio file, one per period."""
    x, rate = read_wav(path)
    try:
        return loudness(x, rate, period), onsets(x, rate, period)
    except AudioError as exc:
        raise AudioError(f"{path}: {exc}") from None


def write_wav(path, samples, sample_rate: int) -> None:
    """Writes 16-bit PCM (mono, or (n, channels)), clipping to [-1, 1]."""
    x = np.clip(np.asarray(samples, dtype=np.float64), -1.0, 1.0)
    channels = 1 if x.ndim == 1 else x.shape[1]
    pcm = np.round(x * 32767.0).astype("<i2")
    with wave.open(str(path), "wb") as w:
        w.setnchannels(channels)
        w.setsampwidth(2)
        w.setframerate(int(sample_rate))
        w.writeframes(pcm.tobytes())
