"""Real recordings for ``marionette bench sync``: found on disk, decoded to
mono at the bench's rate, a fixed excerpt of each.

Where: the folders given with ``--music-dir`` (repeatable), else those in
the environment variable MARIONETTE_MUSIC_DIR (os.pathsep between folders),
else DEFAULT_DIRS: where Debian's ``hyperrogue-music`` installs its 17
tracks (Ogg Vorbis, 44.1 kHz stereo, 48-136 s; ``apt-get install
hyperrogue-music``). Debian's ``fb-music-high`` installs one tracker module
(.xm), which is a score for a module player rather than a recording; it is
not read. Every .ogg, .wav and .flac file under a folder counts (its
subfolders too).

Which: the files sorted by path, then every k-th of them so that COUNT are
taken (k = files // COUNT, at least 1): spread over the folder rather than
the first few of one album; the same files for the same folder. Each is
decoded by the optional `soundfile` package (the ``bench`` extra; only
integer PCM WAV without it, by the standard library), mixed to mono, cut to
its first EXCERPT_S seconds and resampled to the bench's rate (the
synthesized pieces' SAMPLE_RATE). A recording shorter than MIN_S is left
out: the bench's wrong-cue decks start up to 60 s in and 20 s before the
end.
"""
from __future__ import annotations

import importlib.util
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from marionette.errors import MarionetteError
from marionette.music.feature import AudioError, mono, read_wav
from marionette.sim.music import SAMPLE_RATE

DEFAULT_DIRS = ("/usr/share/hyperrogue/music",)
ENV = "MARIONETTE_MUSIC_DIR"
SUFFIXES = (".ogg", ".wav", ".flac")
COUNT = 6                       # recordings the bench plays [1]
EXCERPT_S = 90.0                # each recording's first EXCERPT_S seconds are played [s]
MIN_S = 40.0                    # shorter recordings are left out [s]
INSTALL = ("apt-get install hyperrogue-music (Debian/Ubuntu) and pip install '.[bench]' "
           "(soundfile, for Ogg Vorbis), or give --music-dir DIR (a folder of .ogg/.wav/.flac)")


@dataclass
class Recording:
    name: str                   # its path under its folder, without the suffix
    path: Path
    samples: np.ndarray         # mono [full scale] at sample_rate
    sample_rate: float          # [Hz]

    @property
    def duration(self) -> float:
        return len(self.samples) / self.sample_rate       # [s]


def folders(music_dirs=None) -> list[Path]:
    """The folders searched: music_dirs (the option), else the environment
    variable, else DEFAULT_DIRS. A folder given that does not exist is an
    error; a default one that does not exist is simply empty."""
    given = list(music_dirs or [])
    if not given and os.environ.get(ENV):
        given = [d for d in os.environ[ENV].split(os.pathsep) if d]
    for d in given:
        if not Path(d).is_dir():
            raise MarionetteError(f"--music-dir / {ENV}: {d!r} is not a folder")
    return [Path(d) for d in (given or DEFAULT_DIRS)]


def find(dirs: list[Path]) -> list[tuple[Path, str]]:
    """Every recording under dirs, sorted by path, with its name: its path
    under its folder without the suffix (two albums' track01 stay apart)."""
    return sorted((p, p.relative_to(d).with_suffix("").as_posix()) for d in dirs if d.is_dir()
                  for p in d.rglob("*") if p.is_file() and p.suffix.lower() in SUFFIXES)


def pick(paths: list, count: int = COUNT) -> list:
    """count of paths spread over the sorted list: every k-th, k = len // count."""
    return paths[::max(1, len(paths) // count)][:count]


def resample(x: np.ndarray, rate: float, to: float) -> np.ndarray:
    """x [full scale] at rate [Hz] at the rate to [Hz], band-limited (by the
    DFT: the spectrum cut or padded at the lower Nyquist frequency)."""
    if rate == to or not len(x):        # nothing to do (an empty file is left out as short)
        return x
    n = len(x)
    m = int(round(n * to / rate))
    spectrum = np.fft.rfft(x)
    kept = np.zeros(m // 2 + 1, dtype=complex)
    k = min(len(kept), len(spectrum))
    kept[:k] = spectrum[:k]
    return np.fft.irfft(kept, m) * (m / n)


def decode(path: Path, name: str, excerpt_s: float = EXCERPT_S, rate: float = SAMPLE_RATE) -> Recording:
    """One recording: mono, its first excerpt_s seconds, at rate [Hz]. With
    soundfile only the excerpt is read (a long recording stays cheap)."""
    if importlib.util.find_spec("soundfile") is None:
        x, fs = read_wav(path)
    else:
        import soundfile
        try:
            fs = soundfile.info(str(path)).samplerate
            x, fs = soundfile.read(str(path), frames=int(excerpt_s * fs), dtype="float64")
        except Exception as exc:        # libsndfile's errors: one message naming the file
            raise AudioError(f"{path}: cannot read audio: {exc}") from None
    x = mono(x)[:int(excerpt_s * fs)]
    return Recording(name, path, resample(x, fs, rate), float(rate))


def load(music_dirs=None, count: int = COUNT, excerpt_s: float = EXCERPT_S) -> tuple[list[Recording], str]:
    """The recordings the bench plays, and a note on what was not played
    and why ("" when nothing is missing). An unreadable file is an error
    naming it (AudioError)."""
    dirs = folders(music_dirs)
    paths = find(dirs)
    where = ", ".join(str(d) for d in dirs)
    if not paths:
        return [], f"no recordings (.ogg/.wav/.flac) in {where}; to add them: {INSTALL}"
    notes = []
    if importlib.util.find_spec("soundfile") is None:
        wav = [(p, name) for p, name in paths if p.suffix.lower() == ".wav"]
        if len(wav) < len(paths):
            notes.append(f"{len(paths) - len(wav)} recording(s) in {where} need the soundfile "
                         "package: pip install '.[bench]'")
            paths = wav
    recordings = [decode(p, name, excerpt_s) for p, name in pick(paths, count)]
    short = [r.name for r in recordings if r.duration < MIN_S]
    if short:
        notes.append(f"left out, shorter than {MIN_S:g} s: {', '.join(short)}")
    return [r for r in recordings if r.duration >= MIN_S], "; ".join(notes)
