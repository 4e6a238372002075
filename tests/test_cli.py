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
