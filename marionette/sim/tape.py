"""A tape deck for the music-following benchmark: plays a taught recording
the way a show's recorder does, and says where in the taught music it is.

The deck maps live time t [s] to taught time tau(t) [s]:

    tau(t) = start + integral of speed(t') dt'   (plus a jump, if any)
    speed(t) = speed * (1 + drift(t)) * (1 + wow(t)) * (1 + flutter(t)), 0 during a pause

with drift a slow sine (period 40 s), wow a sine at wow_hz (0.5-1 Hz), and
flutter a sine at flutter_hz (4-10 Hz). The live signal is the taught one
read at tau(t) (linear interpolation), so pitch moves with speed, as on a
tape. A pause stops the tape (silence); after it the tape goes on from where
it stopped. Then, at the live sample rate: hiss (white noise at snr_db below
the mean power of the played music), the volume knob (a gain curve: dB
breakpoints, linear in dB between them; it scales music and hiss alike) and
a reverberant room (exponentially decaying noise, RT60 [s], with the direct
sound).

Ground truth: ``truth[k] = tau(k * T)`` [s] for tick k, i.e. where in the
taught music the live music is when tick k has heard the live audio up to
k * T. The live recording ends where the taught music ends (or at seconds).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from marionette.music.feature import FRAME_PERIOD


@dataclass(frozen=True)
class Deck:
    """How the show's recorder plays; all times [s], depths and speeds [1]."""

    speed: float = 1.0                      # mean speed
    drift: float = 0.0                      # slow drift depth (period 40 s)
    wow: float = 0.0                        # wow depth
    wow_hz: float = 0.7                     # [Hz]
    flutter: float = 0.0                    # flutter depth
    flutter_hz: float = 6.0                 # [Hz]
    gain_db: tuple = ()                     # ((live time, gain [dB]), ...) breakpoints
    snr_db: float | None = None             # noise below the music's mean power [dB]; None: none
    reverb_s: float | None = None           # RT60 of the room; None: dry
    pauses: tuple = ()                      # ((live time, duration), ...)
    start: float = 0.0                      # taught time at live time 0
    jump: tuple | None = None               # (live time, new taught time)
    sample_rate: float = 16000.0            # live sample rate [Hz]
    seconds: float | None = None            # live length; None: until the taught music ends
    seed: int = 0


@dataclass
class Played:
    samples: np.ndarray         # live audio [full scale] at sample_rate
    sample_rate: float          # [Hz]
    truth: np.ndarray           # taught time at tick k [s], k = 0 .. n_ticks - 1
    paused: np.ndarray          # bool per tick: the tape stands still at tick k
    resumes: list[float]        # live times the tape restarted after a pause [s]
    jumps: list[float]          # live times of jumps [s]


def _speed(deck: Deck, t: np.ndarray) -> np.ndarray:
    """Tape speed [1] at live times t [s] (pauses not applied)."""
    rng = np.random.default_rng(deck.seed)
    ph = rng.uniform(0, 2 * np.pi, 3)
    s = deck.speed * (1 + deck.drift * np.sin(2 * np.pi * t / 40.0 + ph[0]))
    s = s * (1 + deck.wow * np.sin(2 * np.pi * deck.wow_hz * t + ph[1]))
    return s * (1 + deck.flutter * np.sin(2 * np.pi * deck.flutter_hz * t + ph[2]))


def warp(deck: Deck, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """tau(t) [s] and a 'tape moving' mask at increasing live times t [s]."""
    dt = np.diff(t, prepend=t[0])
    moving = np.ones(len(t), dtype=bool)
    for at, dur in deck.pauses:
        moving &= ~((t >= at) & (t < at + dur))
    tau = deck.start + np.cumsum(_speed(deck, t) * dt * moving)
    if deck.jump is not None:
        at, to = deck.jump
        after = t >= at
        if np.any(after):
            tau[after] += to - tau[after][0]
    return tau, moving


def play(taught: np.ndarray, taught_rate: float, deck: Deck, period: float = FRAME_PERIOD) -> Played:
    """The live recording of a taught one (mono samples at taught_rate [Hz])."""
    fs = float(deck.sample_rate)
    duration = len(taught) / taught_rate                                    # [s]
    seconds = deck.seconds
    if seconds is None:                  # until the taught music ends: estimate, then cut
        seconds = (duration - min(deck.start, duration)) / max(0.5, deck.speed * (1 - deck.drift)) \
            + sum(d for _, d in deck.pauses) + 2.0
    t = np.arange(int(seconds * fs)) / fs
    tau, moving = warp(deck, t)
    end = np.flatnonzero(tau >= duration - 0.05)
    if deck.seconds is None and len(end):
        t, tau, moving = t[:end[0]], tau[:end[0]], moving[:end[0]]
    y = np.interp(tau * taught_rate, np.arange(len(taught)), taught, left=0.0, right=0.0)
    y *= moving
    rng = np.random.default_rng(deck.seed + 1)
    if deck.snr_db is not None:          # tape hiss: before the volume knob, so the SNR holds
        music = y[moving] if np.any(moving) else y
        power = float(np.mean(music ** 2)) if len(music) else 0.0
        y = y + rng.standard_normal(len(y)) * np.sqrt(power * 10 ** (-deck.snr_db / 10))
    if deck.gain_db:
        at, db = zip(*deck.gain_db)
        y *= 10 ** (np.interp(t, at, db) / 20)
    if deck.reverb_s:
        n = int(deck.reverb_s * fs)
        tail = rng.standard_normal(n) * np.exp(-6.9 * np.arange(n) / n)     # -60 dB at RT60
        tail *= 0.7 / np.sqrt(np.sum(tail ** 2))                            # about -3 dB reverberant
        h = np.concatenate([[1.0], tail[1:]])
        m = 1 << int(np.ceil(np.log2(len(y) + n)))
        y = np.fft.irfft(np.fft.rfft(y, m) * np.fft.rfft(h, m), m)[:len(y)]
    ticks = int(len(t) / fs / period)
    idx = np.minimum((np.arange(ticks) * period * fs).astype(np.int64), max(0, len(t) - 1))
    truth = tau[idx] if len(t) else np.zeros(0)
    # the tape restarts where a pause ends and no other pause holds it (pauses may overlap)
    resumes = sorted({at + dur for at, dur in deck.pauses if at + dur < len(t) / fs
                      and not any(a2 <= at + dur < a2 + d2 for a2, d2 in deck.pauses)})
    jumps = [deck.jump[0]] if deck.jump is not None and deck.jump[0] < len(t) / fs else []
    return Played(samples=y, sample_rate=fs, truth=truth, paused=~moving[idx] if len(t) else
                  np.zeros(0, bool), resumes=resumes, jumps=jumps)
