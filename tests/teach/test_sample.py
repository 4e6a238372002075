"""The bundled teach-in sample: present, small, reproducible, and it runs through
calibrate -> teach -> play as README.md shows."""
import numpy as np

from marionette.music.feature import FRAME_PERIOD, loudness, read_wav, wav_loudness
from marionette.teach import make_sample
from marionette.teach.make_sample import SAMPLE_DIR, sample_music

from conftest import run_cli

FILES = ("markers.csv", "recording.csv", "music.wav")


def test_sample_files_are_bundled_and_small():
    sizes = {name: (SAMPLE_DIR / name).stat().st_size for name in FILES}
    assert sum(sizes.values()) < 1_000_000, sizes
    x, rate = read_wav(SAMPLE_DIR / "music.wav")
    assert rate == 8000 and x.ndim == 1 and 30.0 <= x.size / rate <= 60.0


def _self_similarity(level: np.ndarray, lags) -> np.ndarray:
    """Correlation (Pearson) of a loudness level [dB] with itself ``lag`` frames later."""
    return np.array([np.corrcoef(level[:-lag], level[lag:])[0, 1] for lag in lags])


def test_sample_music_does_not_repeat_bar_by_bar():
    """The music follower finds its place by correlating loudness: music that loops a
    bar has as many equally good places as bars. The bundled song's loudness level
    correlates under 0.8 with itself at every lag from 0.5 s to the longest section
    (8 s; a section that comes back is further away). A loop of its first bar reads
    about 1 at the bar's length, which shows the measure can see a loop."""
    level = 20.0 * np.log10(wav_loudness(SAMPLE_DIR / "music.wav") + 1e-10)      # [dB]
    longest = max(end - start for _, start, end in sample_music().sections)       # [s]
    lags = np.arange(round(0.5 / FRAME_PERIOD), round(longest / FRAME_PERIOD) + 1)  # [frames]
    r = _self_similarity(level, lags)
    assert r.max() < 0.8, f"{r.max():.3f} at {lags[r.argmax()] * FRAME_PERIOD:.2f} s"
    x, rate = read_wav(SAMPLE_DIR / "music.wav")
    bar = 2.0                                                                     # [s]
    loop = np.tile(x[int(4 * rate):int((4 + bar) * rate)], 8)                     # a verse bar, 8 times
    loop_level = 20.0 * np.log10(loudness(loop, rate) + 1e-10)
    assert _self_similarity(loop_level, [round(bar / FRAME_PERIOD)])[0] > 0.99


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
    assert "2250 ticks (45.00 s)" in result.stdout
    # shaped for play's command: some fast turns are reduced (the report names them), and
    # the engine's limits act on no tick of the show
    assert "the engine's limits act on 0 axis-ticks" in result.stdout
    assert "as long as the show" in result.stdout          # the music lasts as long as the dance
    result = run_cli("play", show)
    assert result.returncode == 0, result.stderr
    assert "2250 ticks" in result.stdout and "0 dropped" in result.stdout
    assert "limits acted on 0 axis-ticks" in result.stdout and result.stderr == ""
    # --sample and explicit files do not mix
    (tmp_path / "r.csv").write_text("")
    result = run_cli("teach", "--sample", str(tmp_path / "r.csv"), "--cameras", cameras, "-o", show)
    assert result.returncode == 2 and "not both" in result.stderr
