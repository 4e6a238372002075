"""A synthetic teach-in made once per test session through the CLI: sample files written
by the project's simulator with a fixed seed, cameras calibrated from its markers, and
a show taught from its recording. Shared by the teach and plot command tests:

    @pytest.fixture(scope="session")
    def taught(tmp_path_factory):
        return taught_show.make(tmp_path_factory)
"""
from dataclasses import dataclass
from pathlib import Path

from marionette.teach.make_sample import Sample, write_sample

from conftest import run_cli

SEED = 4242            # not the bundled sample's seed
DURATION = 8.0         # [s]


@dataclass
class Taught:
    directory: Path
    sample: Sample          # the truth behind the files
    cameras: Path           # cameras.toml written by `marionette calibrate`
    show: Path              # show written by `marionette teach` (default options)
    report: str             # what teach printed
    stderr: str             # what teach wrote to stderr (not a terminal: nothing)


_made: list[Taught] = []     # the one Taught of this session


def make(tmp_path_factory) -> Taught:
    if _made:
        return _made[0]
    d = tmp_path_factory.mktemp("teach")
    sample = write_sample(d, seed=SEED, duration=DURATION)
    cameras, show = d / "cameras.toml", d / "show.npz"
    result = run_cli("calibrate", d / "markers.csv", "-o", cameras)
    assert result.returncode == 0, result.stderr
    result = run_cli("teach", d / "recording.csv", "--cameras", cameras, "--music", d / "music.wav",
                     "-o", show)
    assert result.returncode == 0, result.stderr
    _made.append(Taught(d, sample, cameras, show, result.stdout, result.stderr))
    return _made[0]
