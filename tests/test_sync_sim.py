"""``marionette sync-sim`` end to end on WAV files written here: a taught
recording, a live one played by the simulated tape deck (3 % fast, from
10 s in, hiss), and the deck's truth as a CSV."""
from __future__ import annotations

import csv

import numpy as np
import pytest

from marionette import cli
from marionette.music.feature import write_wav
from marionette.music.follower import STATES
from marionette.sim.music import synthesize
from marionette.sim.tape import Deck, play
from conftest import run_cli

T = 0.020


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    d = tmp_path_factory.mktemp("sync")
    piece = synthesize("waltz", seed=2)
    taught = piece.samples[:int(60 * piece.sample_rate)]
    write_wav(d / "taught.wav", taught, int(piece.sample_rate))
    played = play(taught, piece.sample_rate, Deck(speed=1.03, start=10.0, snr_db=30.0,
                                                  sample_rate=22050, seconds=30.0, seed=5))
    write_wav(d / "live.wav", played.samples, 22050)
    with open(d / "truth.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["tick", "position_s"])
        for k, p in enumerate(played.truth):
            w.writerow([k, f"{p:.6f}"])
    return d, played


def read_track(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return rows


@pytest.mark.parametrize("mode,extra", [("smooth", []), ("paper", []), ("smooth", ["--loudness-only"])])
def test_sync_sim_follows_and_reports_accuracy(recordings, capsys, mode, extra):
    d, played = recordings
    out = d / f"track_{mode}{len(extra)}.csv"
    code = cli.main(["sync-sim", "--taught", str(d / "taught.wav"), "--live", str(d / "live.wav"),
                     "--out", str(out), "--mode", mode, "--truth", str(d / "truth.csv"), *extra])
    text = capsys.readouterr().out
    assert code == 0, text
    rows = read_track(out)
    assert list(rows[0]) == ["tick", "time_s", "position_s", "rate", "confidence", "state"]
    n = len(played.truth)
    assert abs(len(rows) - n) <= 2                         # one row per tick of live audio
    assert [int(r["tick"]) for r in rows] == list(range(len(rows)))
    assert float(rows[100]["time_s"]) == pytest.approx(100 * T)
    assert {r["state"] for r in rows} <= set(STATES)
    pos = np.array([float(r["position_s"]) for r in rows])
    m = min(len(pos), n)
    late = np.arange(m) * T >= 5.0
    err = np.abs(pos[:m] - played.truth[:m])[late]
    assert np.mean(err <= (0.02 if mode == "smooth" else 0.05)) >= 0.95
    if mode == "smooth":
        rate = np.array([float(r["rate"]) for r in rows])[:m][late]
        assert abs(np.median(rate) - 1.03) < 0.005
    assert "accuracy, all truth ticks" in text and "within 20 ms" in text and "p95" in text
    assert "first lock" in text


def test_sync_sim_runs_as_a_command(recordings, tmp_path):
    d, _ = recordings
    result = run_cli("sync-sim", "--taught", d / "taught.wav", "--live", d / "live.wav",
                     "--out", tmp_path / "t.csv")
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "t.csv").exists() and "sync-sim (smooth)" in result.stdout


def test_sync_sim_user_errors(recordings, tmp_path, capsys):
    d, _ = recordings
    base = ["sync-sim", "--taught", str(d / "taught.wav"), "--live", str(d / "live.wav"),
            "--out", str(tmp_path / "t.csv")]
    assert cli.main(["sync-sim", "--taught", str(tmp_path / "nope.wav"), "--live", str(d / "live.wav"),
                     "--out", str(tmp_path / "t.csv")]) == 2
    assert "--taught" in (err := capsys.readouterr().err) and "nope.wav: no such file" in err
    bad = tmp_path / "truth.csv"
    bad.write_text("tick,position_s\n0,0.0\n1,abc\n")
    assert cli.main(base + ["--truth", str(bad)]) == 2
    assert f"{bad}:3: position_s 'abc' is not a number" in capsys.readouterr().err
    bad.write_text("frame,pos\n0,0.0\n")
    assert cli.main(base + ["--truth", str(bad)]) == 2
    assert "expected the header 'tick,position_s'" in capsys.readouterr().err
    assert cli.main(base[:-2] + ["--out", str(tmp_path / "no" / "dir" / "t.csv")]) == 2
    assert "--out" in (err := capsys.readouterr().err) and "does not exist" in err
