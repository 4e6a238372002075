"""Real recordings in `marionette bench sync`: found in a folder, decoded
(Ogg Vorbis through soundfile, written here from a synthesized piece),
mixed to mono, resampled to the bench's rate, played through the same tape
decks as the synthesized pieces and reported apart; without recordings the
bench says how to get them and skips their targets."""
from __future__ import annotations

import json

import numpy as np
import pytest
import soundfile

from marionette import cli
from marionette.bench import recordings, sync
from marionette.music.feature import loudness, write_wav
from marionette.sim.music import SAMPLE_RATE, synthesize

RATE = 22050                    # the written recording's rate [Hz], not the bench's
SECONDS = 45.0                  # its length [s]


@pytest.fixture(scope="module")
def music_dir(tmp_path_factory):
    """A folder as a user's: one Ogg Vorbis recording (stereo, 22.05 kHz),
    a WAV too short for the bench, and a file that is no recording."""
    d = tmp_path_factory.mktemp("music")
    x = synthesize("waltz", seed=2, sample_rate=RATE).samples[:int(SECONDS * RATE)]
    soundfile.write(d / "waltz.ogg", np.stack([x, 0.5 * x], axis=1), RATE, format="OGG", subtype="VORBIS")
    (d / "sub").mkdir()
    write_wav(d / "sub" / "short.wav", x[:int(10 * RATE)], RATE)
    (d / "notes.txt").write_text("not music")
    return d


@pytest.fixture(scope="module")
def loaded(music_dir):
    return recordings.load([music_dir])


def test_a_folder_is_decoded_to_mono_at_the_bench_rate(loaded):
    real, note = loaded
    assert [r.name for r in real] == ["waltz"]
    rec = real[0]
    assert rec.sample_rate == SAMPLE_RATE and rec.samples.ndim == 1
    assert rec.duration == pytest.approx(SECONDS, abs=0.05)
    assert "sub/short" in note and f"{recordings.MIN_S:g} s" in note
    # the same music as the piece synthesized at the bench's rate: the
    # loudness frames follow each other (a wrong rate or channel mix would not)
    ref = synthesize("waltz", seed=2).samples[:int(SECONDS * SAMPLE_RATE)]
    a, b = (20 * np.log10(loudness(y, SAMPLE_RATE) + 1e-6) for y in (rec.samples, ref))
    n = min(len(a), len(b))
    assert np.corrcoef(a[:n], b[:n])[0, 1] > 0.95
    # mono: the mean of the channels (0.75 of the left one here)
    assert np.std(rec.samples) == pytest.approx(0.75 * np.std(ref), rel=0.05)


def test_resample_keeps_a_tone_and_drops_what_is_above_nyquist():
    fs = 44100
    t = np.arange(2 * fs) / fs                                        # [s]
    low = recordings.resample(np.sin(2 * np.pi * 1000 * t), fs, SAMPLE_RATE)
    assert len(low) == 2 * SAMPLE_RATE
    spectrum = np.abs(np.fft.rfft(low))
    assert np.argmax(spectrum) * 0.5 == pytest.approx(1000, abs=1)  # bins of 0.5 Hz
    assert np.std(low) == pytest.approx(np.sqrt(0.5), rel=1e-3)
    high = recordings.resample(np.sin(2 * np.pi * 12000 * t), fs, SAMPLE_RATE)
    assert np.std(high) < 1e-3                                        # above 8 kHz: gone, not folded


def test_names_are_paths_under_the_folder(tmp_path):
    for album in ("b", "a"):
        (tmp_path / album).mkdir()
        (tmp_path / album / "track01.FLAC").write_bytes(b"")
    (tmp_path / "cover.jpg").write_bytes(b"")
    found = recordings.find([tmp_path])
    assert [name for _, name in found] == ["a/track01", "b/track01"]


def test_an_unreadable_recording_is_an_error_naming_it(tmp_path, capsys):
    (tmp_path / "broken.ogg").write_bytes(b"OggS not really")
    assert cli.main(["bench", "sync", "--quick", "--music-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "broken.ogg" in err and "Traceback" not in err


def test_pick_spreads_over_the_sorted_files():
    paths = [f"f{i:02d}" for i in range(17)]
    assert recordings.pick(paths, 6) == ["f00", "f02", "f04", "f06", "f08", "f10"]
    assert recordings.pick(paths[:4], 6) == paths[:4]


def test_folders_from_the_option_the_environment_or_the_default(tmp_path, monkeypatch):
    monkeypatch.delenv(recordings.ENV, raising=False)
    assert [str(d) for d in recordings.folders()] == list(recordings.DEFAULT_DIRS)
    monkeypatch.setenv(recordings.ENV, str(tmp_path))
    assert recordings.folders() == [tmp_path]
    other = tmp_path / "other"
    other.mkdir()
    assert recordings.folders([str(other)]) == [other]


def test_a_missing_music_dir_is_an_error_naming_it(capsys):
    assert cli.main(["bench", "sync", "--quick", "--music-dir", "/nonexistent/music"]) == 2
    err = capsys.readouterr().err
    assert "--music-dir" in err and "/nonexistent/music" in err and "Traceback" not in err


def test_real_recordings_run_through_the_tape_decks(loaded):
    real, note = loaded
    with_real = sync.collect(quick=True, seeds=1, real=real, real_note=note)
    alone = sync.collect(quick=True, seeds=1)
    for a, b in zip(with_real, alone):
        # the synthesized pieces' figures do not move when recordings join
        assert (a["within20"], a["within50"], a["lock_s_max"]) == (b["within20"], b["within50"], b["lock_s_max"])
        names = [s["name"] for s in a["scenarios"] if s["real"]]
        assert names and all(n.startswith("real/waltz/") for n in names)
        assert 0.0 <= a["real"]["within20"] <= a["real"]["within50"] <= a["real"]["within200"] <= 1.0
        assert a["real"]["note"] == note
        # together: every measured tick of both, so between the two
        lo, hi = sorted((a["within50"], a["real"]["within50"]))
        assert lo <= a["together"]["within50"] <= hi
        assert list(a["real"]["per_piece"]) == ["real/waltz"]
        assert list(a["together"]["per_piece"]) == ["pop", "real/waltz"]
    by_set = {(r["mode"], r["start"]): r for r in with_real}
    labels = {f"{k} {op} {b:g}" for k, op, b in sync.REAL_TARGETS}
    assert set(by_set["smooth", "unknown"]["real"]["targets"]) == labels
    assert {s["start_s"] for s in by_set["smooth", "cue at top"]["scenarios"]} == {0.0}
    table = sync.format_table(with_real)
    assert "targets, real recordings (smooth mode):" in table
    assert table.count("real/waltz/pauses ") == 4                    # smooth, paper, cued, unknown
    assert "smooth real " in table and "smooth both " in table
    pieces = table.split("\nper piece")[1].split("\n\n")[1].splitlines()
    assert [line.split()[0] for line in pieces[1:]] == ["pop", "real/waltz"]


def test_without_recordings_the_bench_says_how_and_skips(tmp_path, capsys):
    assert sync.main(["--json", "--quick", "--music-dir", str(tmp_path)]) == 0
    results = json.loads(capsys.readouterr().out)
    for r in results:
        assert "apt-get install hyperrogue-music" in r["real"]["skipped"]
        assert "targets" not in r["real"] and not any(s["real"] for s in r["scenarios"])
    table = sync.format_table(results)
    assert "real recordings skipped: no recordings" in table and "--music-dir DIR" in table
    real_targets = table.split("targets, real recordings (smooth mode):\n")[1].splitlines()
    assert real_targets[:len(sync.REAL_TARGETS)] == [
        f"  {f'{k} {op} {b:g}':<36} skipped" for k, op, b in sync.REAL_TARGETS]
