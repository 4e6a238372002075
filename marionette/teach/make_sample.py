"""The bundled sample (marionette/data/sample/): a recording made by the project's own
simulator, so that a new user can run the teach-in at once.

    python -m marionette.teach.make_sample [DIRECTORY]     # default: the bundled one

writes, deterministically (fixed seed, numpy's PCG64):

* ``markers.csv``   - 26 markers on a calibration rig of 9 poles, seen by both cameras
  (0.3 px noise, reported to 0.01 px);
* ``recording.csv`` - 12 s of LED detections of a known dance
  (:mod:`marionette.teach.synthetic`: 0.5 px noise, integer pixels, dropouts, shading);
* ``music.wav``     - 12 s of synthesized music, 8 kHz mono 16-bit: a pentatonic tune at
  120 beats per minute over a bass, growing louder to an accent at every fourth beat.

The dance stays inside the bundled figure's reach after the working-area compression
(yaw within +-1.6 rad, tilts within 5 deg), so the show plays on it unchanged.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from marionette.loudness import write_wav
from marionette.teach.camera import CameraParams, camera_coordinates, project
from marionette.teach.markers import CameraMarkers, write_markers
from marionette.teach.recording import write_recording
from marionette.teach.synthetic import (IMAGE_SIZE, Dance, SyntheticRecording, default_cameras,
                                        synthetic_recording)

SAMPLE_DIR = Path(__file__).resolve().parent.parent / "data" / "sample"
SEED = 1996
DURATION = 12.0          # [s]
SAMPLE_RATE = 8000       # music [Hz]
BEAT = 0.5               # [s], 120 beats per minute
RUCKSACK_HALF_SIDE = 0.2 # b [m], as in the bundled teach settings


def sample_path(name: str) -> Path:
    """A file of the bundled sample."""
    return SAMPLE_DIR / name


def sample_dance(rng: np.random.Generator) -> Dance:
    """A dance of two sinusoids per coordinate with random phases.

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
    return Dance(offset, np.zeros(6), amplitude, frequency, phase)


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


def synth_music(rng: np.random.Generator, duration: float = DURATION,
                rate: int = SAMPLE_RATE) -> np.ndarray:
    """Samples in [-1, 1]: tune + bass; loudness rises through each bar of four beats."""
    t = np.arange(int(round(duration * rate))) / rate
    x = np.zeros_like(t)
    scale = 440.0 * 2.0 ** (np.array([0, 3, 5, 7, 10, 12]) / 12.0)   # A minor pentatonic [Hz]
    n_beats = int(round(duration / BEAT))
    for k in range(n_beats):
        start = k * BEAT
        tau = t - start
        on = (tau >= 0) & (tau < 2 * BEAT)
        level = 0.25 + 0.25 * (k % 4) / 3.0 + (0.3 if k % 4 == 3 else 0.0)   # accent [1]
        f = scale[rng.integers(scale.size)]
        env = np.exp(-tau[on] / 0.25) * np.minimum(1.0, tau[on] / 0.01)
        note = sum(np.sin(2 * np.pi * h * f * tau[on]) / h for h in (1, 2, 3))
        x[on] += level * env * note
        bass = 110.0 if (k // 4) % 2 == 0 else 82.41                     # A2, E2 [Hz]
        x[on] += 0.3 * level * np.exp(-tau[on] / 0.4) * np.sin(2 * np.pi * bass * tau[on])
    return 0.8 * x / np.max(np.abs(x))


@dataclass
class Sample:
    """What was written, and the truth behind it."""

    syn: SyntheticRecording
    markers: list[CameraMarkers]
    music: np.ndarray            # samples [-1, 1]
    sample_rate: int             # [Hz]


def write_sample(directory, seed: int = SEED, duration: float = DURATION,
                 cameras: list[CameraParams] | None = None) -> Sample:
    """Write markers.csv, recording.csv and music.wav into ``directory``."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    cameras = default_cameras() if cameras is None else cameras
    dance = sample_dance(rng)
    syn = synthetic_recording(seed, duration, cameras=cameras, b=RUCKSACK_HALF_SIDE, dance=dance)
    markers = observe_markers(cameras, rng)
    music = synth_music(rng, duration)
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
    parser.add_argument("--duration", type=float, default=DURATION, help="[s]")
    args = parser.parse_args(argv)
    write_sample(args.directory, args.seed, args.duration)
    for name in ("markers.csv", "recording.csv", "music.wav"):
        path = Path(args.directory) / name
        print(f"wrote {path} ({path.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
