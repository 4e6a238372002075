"""The marionette command, run as a user runs it: a separate process."""
import numpy as np

from marionette.recorder import read_flight_record

from conftest import run_cli as run


def test_play_the_demo_in_step_mode(tmp_path):
    flight, frames = tmp_path / "flight.bin", tmp_path / "frames.bin"
    result = run("play", "--record", str(flight), "--output", str(frames))
    assert result.returncode == 0, result.stderr
    assert "1000 ticks" in result.stdout and "0 dropped" in result.stdout
    assert "winch_head" in result.stdout and "light2_tilt" in result.stdout
    meta, records = read_flight_record(flight)
    assert len(records) == 1000 and len(meta["axis_names"]) == 16
    assert frames.stat().st_size == 1000 * (8 + 6 * 16 + 2)    # one version-0 record per tick
    assert np.all(np.isfinite(records["command"]))


def test_play_in_real_time_briefly():
    result = run("play", "--realtime", "--ticks", "25", "--priority", "0")
    assert result.returncode == 0, result.stderr
    assert "in real time: 25 ticks" in result.stdout and "wake latency" in result.stdout


def test_bad_show_is_reported_with_file_and_line(tmp_path):
    show = tmp_path / "bad.csv"
    show.write_text("# marionette show 1\n# tick_period: 0.02\ntick,loudness,x\n0,0,0\n1,0,nan\n")
    result = run("check", str(show))
    assert result.returncode == 2
    assert "bad.csv, line 5" in result.stderr and "'x'" in result.stderr and "nan" in result.stderr
    result = run("check", "--config", str(tmp_path / "none.toml"))
    assert result.returncode == 2 and "none.toml: no such file" in result.stderr


def test_play_follows_music_with_onsets(tmp_path):
    """`play SHOW --music LIVE.wav`: the show stores loudness and onsets, the
    recording is played back as if live (loudness and onset per tick), and
    the engine's playback position follows the tape."""
    from marionette.config import load_config
    from marionette.demo import make_demo_show
    from marionette.music.feature import loudness, onsets, write_wav
    from marionette.sim.music import synthesize
    from marionette.sim.tape import Deck, play

    piece = synthesize("pop", seed=1)
    taught = piece.samples[:int(40 * piece.sample_rate)]
    show = make_demo_show(load_config())
    n = len(loudness(taught, piece.sample_rate))
    show.positions = np.repeat(show.positions[:, :1], n, axis=1)        # held still: only the clock counts
    show.loudness, show.onsets = loudness(taught, piece.sample_rate), onsets(taught, piece.sample_rate)
    show.save(tmp_path / "show.npz")
    played = play(taught, piece.sample_rate, Deck(speed=1.03, start=5.0, snr_db=30.0, sample_rate=22050,
                                                  seconds=25.0, seed=3))
    write_wav(tmp_path / "live.wav", played.samples, 22050)
    flight = tmp_path / "flight.bin"
    result = run("play", str(tmp_path / "show.npz"), "--music", str(tmp_path / "live.wav"),
                 "--record", str(flight), "--ticks", str(len(played.truth)))
    assert result.returncode == 0, result.stderr
    assert "music follower (smooth)" in result.stdout
    _, records = read_flight_record(flight)
    # step mode pushes frame k before tick k: tick k has heard the audio up
    # to (k + 1) T, where the tape is at truth[k + 1]
    m = min(len(records), len(played.truth) - 1)
    late = np.arange(m) * 0.02 >= 8.0
    err = np.abs(records["position"][:m] * 0.02 - played.truth[1:m + 1])[late]     # [s]
    assert np.mean(err <= 0.020) >= 0.95, np.quantile(err, [0.5, 0.95])
