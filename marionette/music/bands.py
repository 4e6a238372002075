"""Band loudness: the music's level in a few wide frequency bands, one row
per 20 ms tick, the same code at teach and at show time.

Why bands: one broadband loudness value per tick cannot tell a bar from its
repeat, nor a room's colouring of a held chord from the music. The bands
see where in the spectrum the energy sits, which differs between a verse
and a chorus played at the same level.

How, per frame k (the framing of LoudnessMeter: frame k starts at
floor(k fs T)):

* the analysis window is the last WINDOW_FRAMES frames up to the end of
  frame k (Hann, 80 ms), so the lowest band holds several FFT bins (a
  20 ms frame alone has bins 50 Hz apart: one bin between 60 and 120 Hz);
  the window ends where the frame ends, so the feature needs no audio from
  later frames, and its delay against the frame is the same at teach and
  show;
* the power spectrum is summed into n bands with triangular weights on a
  log-frequency axis, centres spaced evenly between BAND[0] and BAND[1]
  (60 Hz to 4 kHz, the broadband loudness's band), each weight reaching
  the neighbouring centres. A tape running 6 % fast moves every partial by
  0.08 octave; with bands about an octave wide and soft edges this moves a
  band's level by a fraction of a dB, where hard edges would let a strong
  partial jump from one band to the next;
* returned linear (power as RMS, full scale = 1.0 for a full-scale sine at
  a band's centre).

What the consumer removes: the volume knob multiplies every band by one
factor and a fixed room or speaker colouring each band by its own factor;
after the logarithm both are constant offsets per band, which a
correlation that takes out each band's mean over its window ignores
(`window_correlation`). Sample rate: the bins are 1 / (WINDOW_FRAMES T) =
12.5 Hz apart at any rate and the bands stop at 4 kHz, so any rate from
8 kHz up gives the same frames (tests/test_bands.py).

Why 6 bands and 80 ms (measured with `marionette bench bands` and
tests/test_bands.py on the synthesized pieces, 2026-12-02): more bands
tell more places apart (0.5 s of music on `bench sync`'s calm decks, two
seed sets: 58 % of windows with 6 bands, 65 % with 8, 69 % with 12), but
narrower bands feel the tape's speed more (2.5 s windows of a tape at 0.94
and 1.06 against the stored bands, four pieces: median correlation 0.991
with 6 bands, 0.980 with 8, 0.973 with 12; the worst window 0.86, 0.76 and
0.76). Six bands an octave wide keep a 6 % speed change small. An 80 ms
window told more places apart than 40 ms (8 bands: 65 % against 60 %) and
correlated better at the true place (0.95 against 0.93).
"""
from __future__ import annotations

import numpy as np

from marionette.errors import ArgumentError
from marionette.music.feature import BAND, FRAME_PERIOD, AudioError, LoudnessMeter, loudness, mono, onsets, read_wav

N_BANDS = 6                 # bands between BAND[0] and BAND[1]: an octave apart [1]
WINDOW_FRAMES = 4           # analysis window [frames]: 80 ms, bins 12.5 Hz apart


def band_weights(freqs: np.ndarray, n_bands: int) -> np.ndarray:
    """Weights (n_bands, len(freqs)) of each FFT bin in each band [1]:
    triangles on log2(f) between neighbouring band centres, the first and
    last band flat out to BAND's edges and zero beyond them."""
    lo, hi = np.log2(BAND[0]), np.log2(BAND[1])
    if n_bands == 1:
        centres = np.array([(lo + hi) / 2])
        step = hi - lo
    else:
        step = (hi - lo) / n_bands                      # [octaves] between centres
        centres = lo + step * (np.arange(n_bands) + 0.5)
    octave = np.log2(np.maximum(freqs, 1e-9))
    w = np.clip(1.0 - np.abs(octave[None, :] - centres[:, None]) / step, 0.0, 1.0)
    w[0, octave <= centres[0]] = 1.0                    # flat below the first centre ...
    w[-1, octave >= centres[-1]] = 1.0                  # ... and above the last
    w[:, (freqs < BAND[0]) | (freqs > BAND[1])] = 0.0
    return w


class BandMeter(LoudnessMeter):
    """Turns a stream of audio blocks into band loudness rows: feed() takes
    blocks of any length, as LoudnessMeter's, and returns the rows
    (frames, n_bands) of the frames they completed."""

    def __init__(self, sample_rate: float, period: float = FRAME_PERIOD, n_bands: int = N_BANDS):
        super().__init__(sample_rate, period)
        if not (isinstance(n_bands, int) and 1 <= n_bands <= 32):
            raise ArgumentError(f"n_bands {n_bands!r} is not a whole number from 1 to 32")
        self.n_bands = n_bands
        self.window_len = WINDOW_FRAMES * self.frame_len                # [samples]
        freqs = np.fft.rfftfreq(self.window_len, 1.0 / self.sample_rate)
        self._weights = band_weights(freqs, n_bands)
        self._window = np.hanning(self.window_len)
        # Parseval: a full-scale sine's windowed one-sided bins sum to about
        # N sum(w^2) / 4; scaled so that it reads 1.0 at a band's centre
        self._scale = 4.0 / (self.window_len * np.sum(self._window ** 2))
        self._samples = np.zeros(self.window_len)       # silence before the first sample
        self._first = -self.window_len                  # index of _samples[0] in the stream

    def feed(self, block) -> np.ndarray:
        self._samples = np.concatenate([self._samples, mono(block)])
        ends = []                                       # stream index after each frame's last sample
        k = self._frames
        while True:
            end = int(np.floor(k * self.sample_rate * self.period)) + self.frame_len
            if end > self._first + len(self._samples):
                break
            ends.append(end)
            k += 1
        self._frames = k
        if not ends:
            return np.zeros((0, self.n_bands))
        starts = np.asarray(ends) - self.window_len - self._first
        windows = self._samples[starts[:, None] + np.arange(self.window_len)[None, :]]
        keep = int(np.floor(k * self.sample_rate * self.period)) + self.frame_len - self.window_len
        self._samples = self._samples[keep - self._first:]
        self._first = keep
        return self.window_bands(windows)

    def window_bands(self, windows) -> np.ndarray:
        """Band loudness rows (rows, n_bands) of analysis windows (rows,
        window_len) of mono samples [full scale], each the WINDOW_FRAMES
        frames up to the end of the frame it measures."""
        power = np.abs(np.fft.rfft(np.atleast_2d(windows) * self._window, axis=1)) ** 2
        return np.sqrt(power @ self._weights.T * self._scale)


def bands(samples, sample_rate: float, period: float = FRAME_PERIOD, n_bands: int = N_BANDS) -> np.ndarray:
    """Band loudness rows of a whole recording [full scale], (frames, n_bands)."""
    return BandMeter(sample_rate, period, n_bands).feed(samples)


def wav_bands(path, period: float = FRAME_PERIOD, n_bands: int = N_BANDS) -> np.ndarray:
    """Band loudness rows of an audio file [full scale], (frames, n_bands)."""
    x, rate = read_wav(path)
    try:
        return bands(x, rate, period, n_bands)
    except AudioError as exc:
        raise AudioError(f"{path}: {exc}") from None


def wav_music_frames(path, period: float = FRAME_PERIOD, n_bands: int = N_BANDS):
    """Loudness [full scale], onset strength [dB] and band level rows [full
    scale] of an audio file, one frame per period, the file read once; the
    band rows fitted to the loudness's frames (fit_frames)."""
    x, rate = read_wav(path)
    try:
        loud = loudness(x, rate, period)
        return loud, onsets(x, rate, period), fit_frames(bands(x, rate, period, n_bands), len(loud))
    except AudioError as exc:
        raise AudioError(f"{path}: {exc}") from None


def fit_frames(rows: np.ndarray, n: int) -> np.ndarray:
    """Band level rows cut or padded with NaN rows (no frame) to n frames:
    the band meter's frames beside another meter's n."""
    rows = np.asarray(rows, dtype=np.float64)[:n]
    return np.pad(rows, ((0, n - len(rows)), (0, 0)), constant_values=np.nan)


def correlations(live: np.ndarray, stored: np.ndarray) -> np.ndarray:
    """Joint correlation (as bands.window_correlation) of the window live
    (m, bands) with stored (n, bands) at every offset 0 .. n - m."""
    m = len(live)
    a = live - live.mean(axis=0)
    num = sum(np.correlate(stored[:, b], a[:, b], mode="valid") for b in range(stored.shape[1]))
    c1 = np.vstack([np.zeros((1, stored.shape[1])), np.cumsum(stored, axis=0)])
    c2 = np.vstack([np.zeros((1, stored.shape[1])), np.cumsum(stored ** 2, axis=0)])
    s1, s2 = c1[m:] - c1[:-m], c2[m:] - c2[:-m]
    var_s = np.maximum(s2 - s1 ** 2 / m, 0.0).sum(axis=1)
    den = np.sqrt(np.sum(a * a) * var_s)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / den, np.nan)


def fisher(r):
    """Fisher's z of correlations: differences of z compare correlations
    fairly near 1."""
    return np.arctanh(np.clip(r, -0.999999, 0.999999))


def window_correlation(live_db: np.ndarray, stored_db: np.ndarray) -> float:
    """The joint correlation of two equally long windows of band levels [dB]
    (frames, bands): each band's mean over the window taken out (the volume
    knob and a fixed colouring), then one correlation over every band and
    frame together, so that a band that moves more weighs more. NaN when
    either window is flat."""
    a = live_db - live_db.mean(axis=0)
    b = stored_db - stored_db.mean(axis=0)
    den = np.sqrt(np.sum(a * a) * np.sum(b * b))
    return float(np.sum(a * b) / den) if den > 0 else float("nan")
