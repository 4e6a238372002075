"""Synthesized test music for ``marionette bench sync`` and the follower tests.

A piece is a list of sections (intro, verse, chorus, break, ...) rendered
note by note with numpy: tones with attack/decay envelopes and a few
harmonics, kick, snare and hi-hat. Four styles:

- ``pop``: 4/4 at 112 bpm, drums, bass and chords; verse and chorus repeat,
  the chorus louder, a quiet break with a pad only;
- ``waltz``: 3/4 at 168 bpm, legato melody over bass and chords, crescendo
  and diminuendo, a pianissimo passage, the A section repeated;
- ``ambient``: 70 bpm slow pads, a soft bass pulse and sparse bells: few
  clear onsets, the hard case;
- ``techno``: 4/4 at 128 bpm four-on-the-floor loops, a breakdown without
  kick, a build-up.

A repeated section plays the same notes (the same pattern seed), with the
small differences real repeats have: each note's level varies by up to
+-2 dB and about one note in ten is dropped or added (a fill). Everything is
deterministic for a given seed. Amplitudes are in full scale (|x| < 1).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from marionette.errors import ArgumentError

SAMPLE_RATE = 16000     # [Hz] of the taught recordings the bench makes


@dataclass
class Piece:
    """A rendered piece: samples [full scale] at sample_rate [Hz], and its
    sections as (name, start [s], end [s])."""

    name: str
    style: str
    samples: np.ndarray
    sample_rate: float
    sections: list[tuple[str, float, float]] = field(default_factory=list)

    @property
    def duration(self) -> float:
        return len(self.samples) / self.sample_rate       # [s]


class _Canvas:
    """Mixes note events into one buffer."""

    def __init__(self, seconds: float, sample_rate: float):
        self.fs = float(sample_rate)
        self.x = np.zeros(int(seconds * sample_rate) + int(4 * sample_rate))

    def add(self, start: float, wave: np.ndarray) -> None:
        i = int(round(start * self.fs))
        n = min(len(wave), len(self.x) - i)
        if n > 0 and i >= 0:
            self.x[i:i + n] += wave[:n]


def _env(n: int, fs: float, attack: float, decay: float) -> np.ndarray:
    """Linear attack [s], then exponential decay with time constant decay [s]."""
    t = np.arange(n) / fs
    a = np.minimum(1.0, t / max(attack, 1.0 / fs))
    return a * np.exp(-np.maximum(0.0, t - attack) / decay)


def tone(fs: float, freq: float, dur: float, amp: float, attack=0.01, decay=0.3,
         harmonics=(1.0, 0.5, 0.25)) -> np.ndarray:
    """A note of dur [s] at freq [Hz]; the envelope ends with a 30 ms fade."""
    n = int(dur * fs)
    t = np.arange(n) / fs
    w = sum(h * np.sin(2 * np.pi * freq * (k + 1) * t) for k, h in enumerate(harmonics))
    env = _env(n, fs, attack, decay)
    fade = min(n, int(0.03 * fs))
    if fade:
        env[n - fade:] *= np.linspace(1.0, 0.0, fade)
    return amp * env * w / sum(harmonics)


def kick(fs: float, amp: float) -> np.ndarray:
    n = int(0.25 * fs)
    t = np.arange(n) / fs
    freq = 50.0 + 90.0 * np.exp(-t / 0.03)                     # [Hz], falling
    return amp * np.exp(-t / 0.08) * np.sin(2 * np.pi * np.cumsum(freq) / fs)


def snare(fs: float, amp: float, rng: np.random.Generator) -> np.ndarray:
    n = int(0.2 * fs)
    t = np.arange(n) / fs
    body = np.sin(2 * np.pi * 190.0 * t) * np.exp(-t / 0.04)
    return amp * (0.6 * rng.standard_normal(n) * np.exp(-t / 0.06) + 0.5 * body)


def hat(fs: float, amp: float, rng: np.random.Generator) -> np.ndarray:
    n = int(0.06 * fs)
    noise = np.diff(rng.standard_normal(n + 1))               # tilted to the highs
    return amp * 0.5 * noise * np.exp(-np.arange(n) / fs / 0.015)


def _midi(note: float) -> float:
    return 440.0 * 2.0 ** ((note - 69.0) / 12.0)             # [Hz]


SCALE = np.array([0, 2, 4, 5, 7, 9, 11])                     # major scale [semitones]


def _section_events(style: str, bars: int, beats_per_bar: int, pattern_seed: int,
                    variation_seed: int) -> list[tuple]:
    """The notes of one section: (beat, kind, pitch, duration [beats], level [1]).

    The pattern comes from pattern_seed (so a repeated section repeats it);
    the small per-occurrence differences from variation_seed."""
    rng = np.random.default_rng(pattern_seed)
    var = np.random.default_rng(variation_seed)
    ev = []
    root = 48 + int(rng.integers(0, 7))
    chords = [int(c) for c in rng.choice([0, 3, 4, 5], size=max(1, bars // 2 + 1))]
    for bar in range(bars):
        b0 = bar * beats_per_bar
        degree = chords[bar // 2 % len(chords)]
        chord = [root + SCALE[(degree + k) % 7] + 12 * ((degree + k) // 7) for k in (0, 2, 4)]
        if style == "pop":
            for beat in range(4):
                ev.append((b0 + beat, "kick" if beat % 2 == 0 else "snare", 0, 0, 0.8))
                ev.append((b0 + beat + 0.5, "hat", 0, 0, 0.35))
            ev.append((b0, "tone", chord[0] - 12, 1.8, 0.5))
            ev.append((b0 + 2, "tone", chord[0] - 12, 1.8, 0.45))
            for k, note in enumerate(chord):
                ev.append((b0 + 1 + k * 0.02, "tone", note + 12, 0.9, 0.25))
            for step in range(int(rng.integers(2, 6))):
                ev.append((b0 + float(rng.integers(0, 8)) / 2, "tone",
                           chord[int(rng.integers(0, 3))] + 24, 0.5, 0.35))
        elif style == "waltz":
            ev.append((b0, "tone", chord[0] - 12, 1.0, 0.6))
            ev.append((b0 + 1, "tone", chord[1], 0.8, 0.3))
            ev.append((b0 + 2, "tone", chord[2], 0.8, 0.3))
            beat = 0.0
            while beat < 3:
                dur = float(rng.choice([0.5, 1.0, 1.0, 2.0, 3.0]))
                ev.append((b0 + beat, "legato", root + 12 + SCALE[int(rng.integers(0, 7))],
                           min(dur, 3 - beat), 0.5))
                beat += dur
        elif style == "ambient":
            if bar % 2 == 0:
                for note in chord:
                    ev.append((b0, "pad", note, 2 * beats_per_bar, 0.35))
            for _ in range(int(rng.integers(1, 4))):
                ev.append((b0 + float(rng.integers(0, 2 * beats_per_bar)) / 2, "bell",
                           chord[int(rng.integers(0, 3))] + 24, 2.0, float(rng.uniform(0.2, 0.6))))
            for beat in range(beats_per_bar):         # a soft pulse under the pads
                ev.append((b0 + beat, "tone", chord[0] - 12, 0.6, 0.18))
        elif style == "techno":
            for beat in range(4):
                ev.append((b0 + beat, "kick", 0, 0, 0.9))
                ev.append((b0 + beat + 0.5, "hat", 0, 0, 0.4))
                if rng.random() < 0.3:
                    ev.append((b0 + beat + 0.75, "hat", 0, 0, 0.25))
            ev.append((b0 + 1, "snare", 0, 0, 0.4))
            ev.append((b0 + 3, "snare", 0, 0, 0.4))
            for step in range(8):
                if rng.random() < 0.6:
                    ev.append((b0 + step / 2, "tone", chord[0] - 12 + 12 * int(rng.integers(0, 2)),
                               0.4, 0.45))
    # the small differences of a repeat: levels +-2 dB, about 10 % notes dropped or added
    out = []
    for e in ev:
        if var.random() < 0.05:
            continue
        out.append(e[:4] + (e[4] * 10 ** (var.uniform(-2, 2) / 20),))
    for _ in range(int(0.05 * len(ev))):
        e = ev[int(var.integers(0, len(ev)))]
        out.append((e[0] + 0.5 * float(var.choice([-1, 1])),) + e[1:])
    return [e for e in out if 0 <= e[0] < bars * beats_per_bar]


# Per style: tempo [bpm], beats per bar, and the form: (section name, bars,
# level [dB], crescendo over the section [dB]); equal names repeat.
FORMS = {
    "pop": (112.0, 4, [("intro", 2, -12, 6), ("verse", 8, -6, 0), ("chorus", 8, 0, 0),
                       ("verse", 8, -6, 0), ("chorus", 8, 0, 0), ("break", 4, -26, 0),
                       ("chorus", 8, 0, 0), ("outro", 4, -4, -14)]),
    "waltz": (168.0, 3, [("A", 16, -8, 6), ("A", 16, -4, 0), ("B", 16, -10, 8),
                         ("pp", 8, -28, 0), ("A", 16, -6, 0), ("coda", 8, 0, -18)]),
    "ambient": (70.0, 4, [("a", 8, -10, 6), ("b", 8, -6, 0), ("quiet", 4, -24, 0),
                          ("a", 8, -8, 0), ("b", 6, -6, -12)]),
    "techno": (128.0, 4, [("intro", 8, -10, 6), ("loop", 16, 0, 0), ("breakdown", 8, -18, 0),
                          ("build", 8, -12, 12), ("loop", 16, 0, 0), ("loop2", 16, -2, 0),
                          ("breakdown", 8, -18, 0), ("loop", 16, 0, 0), ("outro", 8, -4, -16)]),
}
STYLES = tuple(FORMS)


def _render_event(c: _Canvas, start: float, kind: str, pitch: float, dur: float, amp: float,
                  rng: np.random.Generator) -> None:
    fs = c.fs
    if kind == "kick":
        c.add(start, kick(fs, amp))
    elif kind == "snare":
        c.add(start, snare(fs, amp, rng))
    elif kind == "hat":
        c.add(start, hat(fs, amp, rng))
    elif kind == "tone":
        c.add(start, tone(fs, _midi(pitch), max(dur, 0.05), amp, 0.005, 0.25))
    elif kind == "legato":
        c.add(start, tone(fs, _midi(pitch), max(dur, 0.05), amp, 0.06, 1.5, (1.0, 0.6, 0.3, 0.15)))
    elif kind == "pad":
        c.add(start, tone(fs, _midi(pitch), dur, amp, 0.8, 6.0, (1.0, 0.3)))
    elif kind == "bell":
        c.add(start, tone(fs, _midi(pitch), dur, amp, 0.002, 0.6, (1.0, 0.0, 0.4, 0.0, 0.2)))


def synthesize(style: str, seed: int = 1, sample_rate: float = SAMPLE_RATE,
               repeat: int = 1, form: tuple | None = None) -> Piece:
    """Render a piece of the given style; repeat > 1 plays the form that many
    times (for longer pieces; later rounds vary like any repeat). form, as an
    entry of FORMS (tempo [bpm], beats per bar, sections), replaces the
    style's own form: the style's notes in another order and length."""
    if style not in FORMS:
        raise ArgumentError(f"unknown style {style!r} (known: {', '.join(STYLES)})")
    bpm, per_bar, form = FORMS[style] if form is None else form
    form = form * repeat
    beat_s = 60.0 / bpm                                         # [s]
    total_beats = sum(bars for _, bars, _, _ in form) * per_bar
    canvas = _Canvas(total_beats * beat_s + 1.0, sample_rate)
    rng = np.random.default_rng(seed)
    pattern_seeds = {name: seed * 1000 + k for k, name in enumerate(dict.fromkeys(n for n, *_ in form))}
    sections = []
    beat0 = 0
    for occurrence, (name, bars, level_db, cresc_db) in enumerate(form):
        events = _section_events(style, bars, per_bar, pattern_seeds[name], seed * 7919 + occurrence)
        length = bars * per_bar
        for beat, kind, pitch, dur, level in events:
            db = level_db + cresc_db * beat / length
            _render_event(canvas, (beat0 + beat) * beat_s, kind, pitch, dur * beat_s,
                          0.25 * level * 10 ** (db / 20), rng)
        sections.append((name, beat0 * beat_s, (beat0 + length) * beat_s))
        beat0 += length
    x = canvas.x[:int((beat0 * beat_s + 1.0) * sample_rate)]
    x *= 0.5 / max(1e-9, float(np.max(np.abs(x))))             # peak at -6 dBFS
    return Piece(name=f"{style}-{seed}", style=style, samples=x, sample_rate=float(sample_rate),
                 sections=sections)
