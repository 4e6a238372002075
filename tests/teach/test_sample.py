"""The bundled teach-in sample: present, small, reproducible, and it runs through
calibrate -> teach -> play as README.md shows."""
import numpy as np

from marionette.loudness import read_wav
from marionette.teach import make_sample
from marionette.teach.make_sample import SAMPLE_DIR

from conftest import run_cli

FILES = ("markers.csv", "recording.csv", "music.wav")


def test_sample_files_are_bundled_and_small():
    sizes = {name: (SAMPLE_DIR / name).stat().st_size for name in FILES}
    assert sum(sizes.values()) < 400_000, sizes
    x, rate = read_wav(SAMPLE_DIR / "music.wav")
    assert rate == 8000 and x.ndim == 1 and 10.0 <= x.size / rate <= 20.0


def test_make_sample_regenerates_the_bundled_files(tmp_path):
    assert make_sample.main([str(tmp_path)]) == 0
    for name in ("markers.csv", "recording.csv"):
        assert (tmp_path / name).read_text() == (SAMPLE_DIR / name).read_text(), name
    new, _ = read_wav(tmp_path / "music.wav")
    old, _ = read_wav(SAMPLE_DIR / "music.wav")
    assert new.shape == old.shape and np.max(np.abs(new - old)) <= 1.0 / 32768   # 1 LSB


def test_bundled_sample_runs_calibrate_teach_play(tmp_path):
    cameras, show = tmp_path / "cameras.toml", tmp_path / "show.npz"
    result = run_cli("calibrate", "--sample", "-o", cameras)
    assert result.returncode == 0, result.stderr
    assert result.stdout.count("converged after") == 2
    result = run_cli("teach", "--sample", "--cameras", cameras, "-o", show)
    assert result.returncode == 0, result.stderr
    assert "598 ticks (11.96 s)" in result.stdout and "infeasible: 0" in result.stdout
    result = run_cli("play", show)
    assert result.returncode == 0, result.stderr
    assert "598 ticks" in result.stdout and "0 dropped" in result.stdout
    # --sample and explicit files do not mix
    result = run_cli("teach", "--sample", str(tmp_path / "r.csv"), "--cameras", cameras, "-o", show)
    assert result.returncode == 2 and "not both" in result.stderr
