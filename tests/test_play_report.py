"""What `marionette play` tells the operator about the live music: lines
when it is not followed, the share of the show that ran so, the exit status,
warnings about a live recording (silent, truncated, another piece), and the
follower's input latency (the figure's, else the sound card's)."""
import dataclasses

import numpy as np
import pytest

from conftest import figure_dict, make_figure, run_cli as run
from marionette._core import FLAG_END, FLAG_UNFOLLOWED
from marionette.config import config_from_dict, default_config_path, load_config
from marionette.demo import make_demo_show
from marionette.engine import Engine
from marionette.music.feature import loudness, onsets, write_wav
from marionette.music.follower import c_options, sync_ticks
from marionette.music.report import (LostWatcher, choose_latency, follow_share, lost_events,
                                     recording_warnings)
from marionette.recorder import read_flight_record
from marionette.show import Show
from marionette.sim.music import synthesize
from marionette.sim.tape import Deck, play

FS = 22050          # live sample rate [Hz]
T = 0.020           # [s]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A 40 s show taught from a pop piece (the demo figure held still), and
    live recordings of it: a good one, one that loses the place (8 s of a
    waltz in the middle, then the tape jumps back), silence, 8 s of it, and
    another piece."""
    d = tmp_path_factory.mktemp("play_report")
    piece = synthesize("pop", seed=1)
    taught = piece.samples[:int(40 * piece.sample_rate)]
    show = make_demo_show(load_config())
    n = len(loudness(taught, piece.sample_rate))
    show.positions = np.repeat(show.positions[:, :1], n, axis=1)
    show.loudness, show.onsets = loudness(taught, piece.sample_rate), onsets(taught, piece.sample_rate)
    show.save(d / "show.npz")
    good = play(taught, piece.sample_rate, Deck(speed=1.03, start=5.0, snr_db=30.0, sample_rate=FS,
                                                 seconds=25.0, seed=3))
    write_wav(d / "good.wav", good.samples, FS)
    other = synthesize("waltz", seed=2)
    write_wav(d / "other.wav", other.samples[:int(30 * other.sample_rate)], int(other.sample_rate))
    lost = play(taught, piece.sample_rate, Deck(speed=1.0, snr_db=30.0, sample_rate=FS, seconds=38.0,
                                                 jump=(18.0, 6.0), seed=5)).samples
    waltz = other.samples[int(60 * other.sample_rate):int(68 * other.sample_rate)]
    t = np.arange(8 * FS) / FS                                                      # [s]
    lost[10 * FS:18 * FS] = 0.5 * np.interp(t * other.sample_rate, np.arange(len(waltz)), waltz)
    write_wav(d / "lost.wav", lost, FS)
    write_wav(d / "silent.wav", np.zeros(30 * FS), FS)
    write_wav(d / "short.wav", good.samples[:8 * FS], FS)
    hold = d / "hold.toml"
    hold.write_text(default_config_path().read_text() + '\n[follow]\non_lost = "hold"\nlatency = 0.04\n')
    return d


def play_music(files, wav, *extra):
    flight = files / f"{wav}.bin"
    result = run("play", files / "show.npz", "--music", files / wav, "--record", flight, *extra)
    return result, read_flight_record(flight)[1]


def test_lost_and_found_lines_and_the_share(files):
    result, records = play_music(files, "lost.wav")
    assert result.returncode == 0, result.stderr
    lost = (records["flags"] & FLAG_UNFOLLOWED) != 0
    first = np.flatnonzero(lost)[0]
    again = first + np.flatnonzero(~lost[first:])[0]
    lines = result.stderr.splitlines()
    # step mode: after the run, from the records, at the show time of the ticks
    assert lines == [f"music not followed from show time {first * T:.2f} s (last place "
                     f"{records['position'][first - 1] * T:.2f} s of the music; on_lost flywheel: "
                     f"the show plays on at the last rate)",
                     f"music followed again at show time {again * T:.2f} s, after "
                     f"{(again - first) * T:.2f} s"], result.stderr
    # tick 0 has heard no frame yet (step mode gives frame k - 1 to tick k)
    searching = np.sum(np.isin(records["follow_state"][1:], (0, 4)))     # searching, waiting
    assert 0.05 < searching / len(records) < 0.5
    assert (f"music not followed: {searching / len(records):.0%} of the show searching or waiting for it "
            f"({searching * T:.2f} s from the first live frame at 0.02 s), {np.sum(lost) * T:.2f} s of it "
            f"after the first place, lost 1 time(s); on_lost flywheel") in result.stdout
    assert "input latency 0 ms (default)" in result.stdout
    assert "NOT FOLLOWED" not in result.stdout


def test_hold_from_the_figure_and_its_latency(files):
    result, records = play_music(files, "lost.wav", "--config", files / "hold.toml")
    assert result.returncode == 0, result.stderr
    assert "on_lost hold: the figure holds there" in result.stderr
    assert "input latency 40 ms (the figure's [follow] latency)" in result.stdout
    lost = (records["flags"] & FLAG_UNFOLLOWED) != 0
    assert lost.sum() > 100 and np.all(records["rate"][lost] == 0.0)
    assert np.ptp(records["position"][lost]) == 0.0          # one loss: one held place


def test_a_silent_recording_is_warned_about_and_play_exits_1(files):
    result, records = play_music(files, "silent.wav")
    path = files / "silent.wav"
    assert result.returncode == 1
    err = result.stderr.splitlines()
    assert err[0] == f"warning: live recording {path} is silent (every frame under 0.0001 full " \
                     f"scale RMS); the music cannot be followed"
    assert f"warning: the music follower never locked on {path} in {len(records)} ticks" in err[1]
    # the show ran to its end all the same, and the last line says why the status is 1
    assert len(records) == 2000 and "music not followed: 100% of the show searching or waiting" \
        in result.stdout
    assert result.stdout.splitlines()[-1] == ("NOT FOLLOWED: the music was not followed for 100% of "
                                              "the show (more than 50%); exit status 1")


def test_a_truncated_recording_is_warned_about(files):
    result, records = play_music(files, "short.wav", "--start", "5")
    assert result.returncode == 0, result.stderr
    assert result.stderr.splitlines()[0] == (
        f"warning: live recording {files / 'short.wav'} is 8.00 s long, less than 50% of the show's "
        f"music from the cue at 5 s (35.00 s): truncated?")
    # the follower plays on at its rate past the recording's end, to the show's end (FLAG_END),
    # where play ends: fewer ticks than the show has, as it started 5 s in
    assert records["flags"][-1] & FLAG_END and records["position"][-1] == 1999 and len(records) < 2000
    # the whole recording from the cue at 30 s is long enough: no warning
    result, _ = play_music(files, "short.wav", "--start", "30", "--ticks", "50")
    assert "truncated" not in result.stderr


def test_another_piece_is_never_locked_on(files):
    result, records = play_music(files, "other.wav")
    assert result.returncode == 1
    assert not np.any(records["follow_state"] == 1)
    # the cue at the top is refuted (a line when the music becomes unfollowed), then the warning
    assert result.stderr.splitlines()[-1] == (
        f"warning: the music follower never locked on {files / 'other.wav'} in 2000 ticks: another "
        f"piece than the show's, or no music?")


def test_a_good_recording_gets_no_warning(files):
    result, _ = play_music(files, "good.wav", "--start", "5")     # the tape starts 5 s in
    assert result.returncode == 0 and result.stderr == "", result.stderr


def test_real_time_with_the_watcher_briefly(files, tmp_path):
    """In real time the lines come from the watcher thread; a 1 s run has not
    locked yet, so the show searched from its first live frame on (which
    comes a few ticks in, later on a loaded machine): exit 1 with the
    verdict last, its share the flight record's."""
    record = tmp_path / "flight.bin"
    result = run("play", files / "show.npz", "--music", files / "good.wav", "--realtime",
                 "--ticks", "50", "--priority", "0", "--start", "unknown", "--record", record)
    assert result.returncode == 1 and "Traceback" not in result.stderr, result.stderr
    assert "in real time: 50 ticks" in result.stdout
    _, records = read_flight_record(record)
    share = follow_share(records)
    assert share.searching == share.ticks - share.before_music and share.share > 0.5
    assert result.stdout.splitlines()[-1].startswith(
        f"NOT FOLLOWED: the music was not followed for {share.share:.0%} of the show")


def test_recording_warnings_unit():
    rng = np.random.default_rng(1)
    music = 0.1 * 10 ** (rng.uniform(-30, 0, 1000) / 20)                     # 20 s [full scale]
    assert recording_warnings("m.wav", music, T, 30.0, None) == []
    assert recording_warnings("m.wav", music, T, 45.0, None)[0].endswith("(45.00 s): truncated?")
    assert recording_warnings("m.wav", music, T, 45.0, 10.0) == []
    hiss = 0.01 * (1 + 0.05 * rng.standard_normal(1000))                     # steady: 1 dB
    assert "has no level range" in recording_warnings("h.wav", hiss, T, 20.0, 0.0)[0]
    assert "is silent" in recording_warnings("s.wav", np.full(1000, 5e-5), T, 20.0, 0.0)[0]
    assert "is silent" in recording_warnings("e.wav", np.zeros(0), T, 20.0, 0.0)[0]


def test_the_watcher_reads_what_the_records_say():
    """The real-time watcher, made to look after every tick of a step-mode
    run, prints the lines lost_events makes from the records afterwards."""
    piece = synthesize("techno", seed=4)
    stored = loudness(piece.samples, piece.sample_rate)
    deck = Deck(speed=0.98, snr_db=30.0, sample_rate=16000, start=20.0, seconds=40.0, seed=2)
    played = play(piece.samples, piece.sample_rate, deck)
    live = sync_ticks(loudness(played.samples, played.sample_rate))
    live[600:1000] = live[2000:1600:-1]                          # 8 s of it backwards: lost
    config = make_figure(1, max_speed=50.0, max_accel=5000.0)
    show = Show(axis_names=config.axis_names, units=["m"], positions=np.zeros((1, len(stored))),
                loudness=stored, tick_period=T)
    with Engine(config, show, follow="smooth", record=True) as e:
        out = []

        class Out:
            def write(self, text):
                out.append(text)

            def flush(self):
                pass

        watcher = LostWatcher(e, T, "flywheel", out=Out())
        for value in live:
            if np.isfinite(value):
                e.push_loudness(float(value))
            e.step(1)
            watcher.look()
        records = e.records()
    expected = lost_events(records["flags"], records["position"], T, "flywheel")
    assert len(expected) >= 2 and watcher.lines == expected
    assert "".join(out) == "".join(line + "\n" for line in expected)
    assert follow_share(records).losses == len(expected[::2])


def test_the_latency_the_follower_uses():
    assert choose_latency(None, 0.040) == (0.040, "the sound card's input latency")
    assert choose_latency(0.0, 0.040) == (0.0, "the figure's [follow] latency")   # set to 0: kept
    assert choose_latency(0.01, None) == (0.01, "the figure's [follow] latency")
    assert choose_latency(None, None) == (0.0, "default")
    # the figure leaves latency out: None, which the C options read as 0
    d = figure_dict()
    follow = config_from_dict(d, "f.toml").follow
    assert follow.latency is None and c_options(follow, 0.02)["latency"] == 0.0
    d["follow"] = {"latency": 0.0}
    assert config_from_dict(d, "f.toml").follow.latency == 0.0
    d["follow"] = {"latency": 0.05}
    follow = config_from_dict(d, "f.toml").follow
    assert follow.latency == 0.05 and c_options(follow, 0.02)["latency"] == 0.05
    # what play.run builds the engine with when the sound card reports 40 ms
    chosen, _ = choose_latency(None, 0.040)
    follow = dataclasses.replace(config_from_dict(figure_dict(), "f.toml").follow, latency=chosen)
    assert c_options(follow, 0.02)["latency"] == 0.040


def test_the_share_counts_searching_once_music_is_heard():
    """Ticks before the first live frame (a sound card opening) are not
    unfollowed; searching after it is, and more than half of the show makes
    the verdict."""
    from marionette.music.report import verdict_line
    rec = np.zeros(1000, dtype=[("follow_state", "<i4"), ("flags", "<u4"), ("live_loudness", "<f8")])
    rec["live_loudness"][:300] = np.nan          # no frame for 6 s
    rec["follow_state"][:700] = 0                # searching until tick 700, then locked
    rec["follow_state"][700:] = 1
    rec["live_loudness"][300:] = 0.1
    s = follow_share(rec)
    assert (s.before_music, s.searching, s.share, s.locked) == (300, 400, 0.4, True)
    assert verdict_line(s) is None
    rec["follow_state"][700:720] = 0             # 20 more ticks: more than half
    rec["flags"][700:720] = FLAG_UNFOLLOWED
    s = follow_share(rec)
    assert (s.searching, s.unfollowed, s.losses) == (420, 20, 1)
    assert s.share == pytest.approx(0.42)
    rec["live_loudness"][:300] = 0.0             # a silent source still brings frames
    assert follow_share(rec).share == pytest.approx(0.72)
    assert verdict_line(follow_share(rec)).startswith("NOT FOLLOWED: the music was not followed for 72%")
