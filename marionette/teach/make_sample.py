"""The bundled sample (marionette/data/sample/): a recording made by the project's own
simulator, so that a new user can run the teach-in at once.

    python -m marionette.teach.make_sample [DIRECTORY]     # default: the bundled one

writes, deterministically (fixed seed, numpy's PCG64):

* ``markers.csv``   - 26 markers on a calibration rig of 9 poles, seen by both cameras
  (0.3 px noise, reported to 0.01 px);
* ``recording.csv`` - LED detections of a known dance, as long as the music (45 s)
  (:mod:`marionette.teach.synthetic`: 0.5 px noise, integer pixels, dropouts, shading);
* ``music.wav``     - 45 s of a song from the project's synthesizer
  (:mod:`marionette.sim.music`, pop style: drums, bass, chords, a melody), 8 kHz mono
  16-bit: 120 beats per minute, intro, verse, chorus, break, verse, chorus, outro. The
  verse and the chorus come back once (the same notes with a repeat's small
  differences); nothing else repeats: the loudness level correlates at most 0.40
  with itself 0.5 to 10 s later (a tune that loops one 2 s bar reads 0.99 at 2 s),
  so the music follower can tell where in the song the live music is.

The dance stays inside the bundled figure's reach after the working-area compression
(yaw within +-1.6 rad, tilts within 5 deg) for any length: it is a sum of sinusoids
whose amplitudes add up to less than that. It swells in over the first 2 s and dies
away over the last 2 s (FadedDance), so it starts and ends at rest and the show's
last move can stop in time. The show plays on the figure unchanged.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from marionette.music.feature import write_wav
from marionette.sim.music import Piece, synthesize
from marionette.teach.camera import CameraParams, camera_coordinates, project
from marionette.teach.markers import CameraMarkers, write_markers
from marionette.teach.recording import write_recording
from marionette.teach.synthetic import (IMAGE_SIZE, Dance, SyntheticRecording, default_cameras,
                                        synthetic_recording)
from marionette.errors import ArgumentError

SAMPLE_DIR = Path(__file__).resolve().parent.parent / "data" / "sample"
SEED = 1996
SAMPLE_RATE = 8000       # music [Hz]
RUCKSACK_HALF_SIDE = 0.2 # b [m], as in the bundled teach settings
FADE = 2.0               # [s] the dance swells in and dies away over this at either end
# The song, in the synthesizer's form notation: tempo [beats per minute], beats per bar,
# and (section, bars, level [dB], crescendo over the section [dB]); equal names play
# the same notes. 22 bars of 2 s and 1 s for the last notes to ring out: 45 s.
SONG_FORM = (120.0, 4, [("intro", 2, -12, 6), ("verse", 4, -6, 0), ("chorus", 4, 0, 0),
                        ("break", 2, -20, 0), ("verse", 4, -6, 0), ("chorus", 4, 0, 0),
                        ("outro", 2, -4, -14)])


def sample_path(name: str) -> Path:
    """A file of the bundled sample."""
    return SAMPLE_DIR / name


@dataclass
class FadedDance(Dance):
    """A Dance whose sinusoids are scaled by an envelope: from 0 to 1 over the first
    ``fade`` [s], 1, and back to 0 over the last ``fade`` before ``end`` [s] (raised
    cosines). The dancer starts and ends at rest at the offset, so the show's last
    move has time to stop."""

    end: float = 0.0                        # [s]
    fade: float = FADE                      # [s]

    def envelope(self, t) -> tuple[np.ndarray, np.ndarray]:
        """The envelope g(t) [1] and its time derivative [1/s] at times t (K,) [s]."""
        u = np.clip(np.minimum(t, self.end - t) / self.fade, 0.0, 1.0)   # 0 at an end, 1 inside
        du = np.where(t < self.end - t, 1.0, -1.0) / self.fade            # [1/s] where not clipped
        g = 0.5 * (1.0 - np.cos(np.pi * u))
        return g, 0.5 * np.pi * np.sin(np.pi * u) * du                    # sin is 0 where clipped

    def pose(self, t) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, float))
        steady = self.offset + self.rate * t[:, None]
        return steady + self.envelope(t)[0][:, None] * (super().pose(t) - steady)

    def velocity(self, t) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, float))
        g, dg = self.envelope(t)
        swing = super().pose(t) - self.offset - self.rate * t[:, None]   # the sinusoids alone
        return self.rate + g[:, None] * (super().velocity(t) - self.rate) + dg[:, None] * swing


def sample_dance(rng: np.random.Generator, duration: float) -> FadedDance:
    """A dance of duration [s], two sinusoids per coordinate with random phases,
    faded in and out (FadedDance).

    x0, y0 within +-1.6 m (of the 4 m x 4 m area), z0 1.3 m +- 0.12 m, roll and pitch
    within +-5 deg, yaw within +-1.6 rad; frequencies 0.1-0.7 Hz.
    """
    amplitude = np.array([[1.0, 0.45],        # x0 [m]
                          [0.9, 0.35],        # y0 [m]
                          [0.08, 0.04],       # z0 [m]
                          [0.06, 0.025],      # phi [rad]
                          [0.05, 0.03],       # theta [rad]
                          [1.2, 0.35]])       # psi [rad]
    frequency = np.array([[0.12, 0.30],
                          [0.09, 0.35],
                          [0.50, 1.00],
                          [0.40, 0.70],
                          [0.30, 0.60],
                          [0.10, 0.35]])      # [Hz]
    phase = rng.uniform(0.0, 2.0 * np.pi, (6, 2))
    offset = np.array([0.0, 0.0, 1.3, 0.0, 0.0, 0.0])
    return FadedDance(offset, np.zeros(6), amplitude, frequency, phase, end=duration)


def rig_markers() -> tuple[list[str], np.ndarray]:
    """Marker names and positions (26, 3) [m]: 8 poles around the area with markers at
    0, 1 and 2 m, and one pole in the centre with markers at 0.5 and 1.5 m."""
    points = []
    for x in (-1.8, 0.0, 1.8):
        for y in (-1.8, 0.0, 1.8):
            heights = (0.5, 1.5) if x == 0.0 and y == 0.0 else (0.0, 1.0, 2.0)
            points.extend((x, y, z) for z in heights)
    names = [f"M{i + 1:02d}" for i in range(len(points))]
    return names, np.array(points)


def observe_markers(cameras: list[CameraParams], rng: np.random.Generator,
                    noise_px: float = 0.3) -> list[CameraMarkers]:
    """The rig as every camera sees it (markers outside the image are left out)."""
    names, X = rig_markers()
    out = []
    for cam in cameras:
        pix = project(cam, X) + rng.normal(0.0, noise_px, (len(names), 2))
        pix = np.round(pix, 2)
        seen = ((camera_coordinates(cam, X)[:, 1] > 0)
                & np.all((pix >= 0) & (pix <= np.array(IMAGE_SIZE) - 1), axis=1))
        idx = np.flatnonzero(seen)
        out.append(CameraMarkers([names[i] for i in idx], X[idx], pix[idx], []))
    return out


def sample_music(seed: int = SEED) -> Piece:
    """The sample's song: samples [-1, 1] at SAMPLE_RATE [Hz] and its sections [s]."""
    return synthesize("pop", seed, SAMPLE_RATE, form=SONG_FORM)


@dataclass
class Sample:
    """What was written, and the truth behind it."""

    syn: SyntheticRecording
    markers: list[CameraMarkers]
    music: np.ndarray            # samples [-1, 1]
    sample_rate: int             # [Hz]


def write_sample(directory, seed: int = SEED, duration: float | None = None,
                 cameras: list[CameraParams] | None = None) -> Sample:
    """Write markers.csv, recording.csv and music.wav into ``directory``.

    duration [s]: of the recording and the music; None: the whole song (45 s); a
    shorter one cuts the song (the tests teach a few seconds of it)."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    song = sample_music(seed)
    if duration is None:
        duration = song.duration
    elif not 0.0 < duration <= song.duration:
        raise ArgumentError(f"duration {duration!r} s: the sample's song lasts {song.duration:g} s")
    music = song.samples[:int(round(duration * SAMPLE_RATE))]
    rng = np.random.default_rng(seed)
    cameras = default_cameras() if cameras is None else cameras
    dance = sample_dance(rng, duration)
    syn = synthetic_recording(seed, duration, cameras=cameras, b=RUCKSACK_HALF_SIDE, dance=dance)
    markers = observe_markers(cameras, rng)
    note = (f"sample made by `python -m marionette.teach.make_sample` (seed {seed}); "
            "units: x, y, z [m], R, T [pixel]")
    write_markers(directory / "markers.csv", markers, comment=note)
    write_recording(directory / "recording.csv", syn.recording, n_cameras=len(cameras))
    write_wav(directory / "music.wav", music, SAMPLE_RATE)
    return Sample(syn, markers, music, SAMPLE_RATE)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m marionette.teach.make_sample",
                                     description="Regenerate the bundled teach-in sample.")
    parser.add_argument("directory", nargs="?", default=str(SAMPLE_DIR),
                        help=f"where to write (default: {SAMPLE_DIR})")
    parser.add_argument("--seed", type=int, default=SEED)
    parser.add_argument("--duration", type=float, default=None,
                        help="[s] of recording and music (default: the whole song)")
    args = parser.parse_args(argv)
    write_sample(args.directory, args.seed, args.duration)
    for name in ("markers.csv", "recording.csv", "music.wav"):
        path = Path(args.directory) / name
        print(f"wrote {path} ({path.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
