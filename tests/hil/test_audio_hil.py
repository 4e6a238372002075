"""The live sound-card source through a real audio stack: music played into
a PulseAudio null sink is recorded from its monitor by PortAudio (ALSA's
'pulse' device) and drives the engine's follower; killing the server
mid-show is reported once, clearly, reaches the engine (the flight record
says the source was lost from then on) and makes `play` exit 1. No part of
PortAudio is replaced (audio_support.py sets the stack up)."""
import os
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np
import pytest

from audio_support import (SINK, play_into_sink, pulse_device, recording_env, start_server,
                           stop_server)
from hil_support import dance_from_home
from marionette._core import FLAG_SOURCE_LOST, FLAG_UNFOLLOWED
from marionette.config import load_config
from marionette.music.bands import fit_frames, wav_bands
from marionette.music.feature import AudioError, wav_frames, write_wav
from marionette.music.sound_card import SoundCard, _choose, input_devices
from marionette.recorder import read_flight_record
from marionette.show import Show
from marionette.sim.music import synthesize

T = 0.020                       # tick period of the bundled figure [s]
# measured here (2 cores, PulseAudio 16.1, PortAudio 19.6): the first frame
# 1.0 to 2.0 s after the recording starts, the lock 3.9 to 5.3 s after the
# first frame (pop, seed 5, from its start)
LOCK_WITHIN = 8.0               # after the first frame [s]
# from the server's kill to the first flight record that says the source was
# lost: PortAudio's stream ends (or 0.5 s of no audio), the watchdog's next
# look (0.1 s) and its wait for PortAudio's lines (0.1 s), then a tick
LOST_WITHIN = 0.6               # [s]


@pytest.fixture(scope="module")
def pulse():
    """The PortAudio input that records through PulseAudio."""
    return pulse_device()


@pytest.fixture
def server_back():
    """Starts the server again after a test that ended it."""
    yield
    start_server()


@pytest.fixture(scope="module")
def music(tmp_path_factory):
    """A non-repeating piece as WAV, and a show taught to it (.npz) with its
    band levels, as teach stores them: the sound card then measures them live."""
    d = tmp_path_factory.mktemp("audio")
    piece = synthesize("pop", seed=5)
    wav = d / "music.wav"
    write_wav(wav, piece.samples, int(piece.sample_rate))
    stored, stored_onsets = wav_frames(wav)
    figure = load_config(None)
    dance = dance_from_home(figure, len(stored) * figure.tick_period, seed=10)
    show = d / "show.npz"
    Show(axis_names=dance.axis_names, units=dance.units, positions=dance.positions,
         loudness=stored, onsets=stored_onsets, bands=fit_frames(wav_bands(wav), len(stored)),
         tick_period=figure.tick_period).save(show)
    return wav, show


def without_status(err: str) -> list[str]:
    """stderr's lines but play's headless status lines (docs/console.md) and
    the limiter's warning (marionette/limiter_report.py: a show followed at a
    changing rate may ask a little more than the limits allow)."""
    return [line for line in err.splitlines()
            if not line.startswith("status: ") and not line.startswith("warning: the limits cut")]


def play_cli(show, device, ticks, record=None, start="0"):
    """`marionette play SHOW --audio-device DEVICE --realtime --start START`,
    recording the test sink's monitor; the Popen."""
    args = [sys.executable, "-m", "marionette.cli", "play", str(show), "--audio-device", str(device),
            "--realtime", "--ticks", str(ticks), "--priority", "0", "--start", start]
    if record is not None:
        args += ["--record", str(record)]
    return subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=recording_env(), cwd=tempfile.gettempdir())


def test_frames_arrive_at_50_hz_and_the_latency_is_reported(pulse, music, monkeypatch):
    monkeypatch.setenv("PULSE_SOURCE", f"{SINK}.monitor")
    wav, _ = music
    arrivals, values = [], []

    def take(value, onset):
        arrivals.append(time.monotonic())
        values.append(value)

    player = play_into_sink(wav)
    try:
        with SoundCard(take, device=pulse["index"], onsets=True) as source:
            assert source.latency is not None and 0 < source.latency < 0.5, source.latency
            deadline = time.monotonic() + 6.0
            while (not arrivals or arrivals[-1] - arrivals[0] < 4.0) and time.monotonic() < deadline:
                time.sleep(0.05)
    finally:
        player.kill()
        player.wait()
    assert arrivals, "no frame in 6 s"
    assert source.lost_reason is None and source.overflows == 0, (source.lost_reason, source.overflows)
    t = np.array(arrivals) - arrivals[0]
    steady = t[t >= 1.0]        # after the first second: the stream may catch up at first
    rate = (len(steady) - 1) / (steady[-1] - steady[0])           # [frames/s]
    assert 48.5 < rate < 51.5, rate
    assert np.max(np.diff(steady)) < 0.1, np.max(np.diff(steady))  # no gap of 5 frames
    assert np.max(values) > 1e-3, np.max(values)                    # the music, not silence
    print(f"latency {source.latency * 1e3:.0f} ms, {rate:.2f} frames/s")


def test_the_show_follows_music_from_the_sound_card(pulse, music, tmp_path):
    wav, show = music
    # 20 s: a first lock within LOCK_WITHIN of the first frame (up to 2 s late)
    # keeps the searching share under half, which would make play exit 1
    ticks = 1000
    flight = tmp_path / "flight.bin"
    player = play_into_sink(wav)
    started = time.monotonic()                      # the music starts about now [s]
    try:
        # the index as a command line gives it: a string of digits
        # the music plays before play starts (its start-up, 1-2 s): the top
        # is not where it begins, so the cue is unknown (a cue at the top is
        # refuted, rightly, and the search takes over: play says so)
        proc = play_cli(show, pulse["index"], ticks, record=flight, start="unknown")
        out, err = proc.communicate(timeout=40)
    finally:
        player.kill()
        player.wait()
    assert proc.returncode == 0, err
    assert without_status(err) == [], err            # no lines but play's status lines
    assert f"audio input 'pulse': " in out and "LOST" not in out, out
    assert "(the sound card's input latency)" in out, out
    _, rec = read_flight_record(flight)
    t = rec["time_ns"] * 1e-9 - started             # CLOCK_MONOTONIC, as time.monotonic() [s]
    live = rec["live_loudness"]
    heard = np.flatnonzero(np.isfinite(live))
    assert len(heard), "no frame reached the engine"
    first = heard[0]
    # a new frame nearly every tick from the first on (one frame per 20 ms)
    assert np.mean(np.diff(live[first:]) != 0) > 0.85, np.mean(np.diff(live[first:]) != 0)
    locked = np.flatnonzero(rec["follow_state"] == 1)
    assert len(locked), "the follower never locked"
    assert (locked[0] - first) * T < LOCK_WITHIN, (locked[0] - first) * T
    after = locked[locked > locked[0] + 50]         # a second after the lock
    assert len(after) > 0.9 * (ticks - locked[0] - 50), len(after)    # and it stays locked
    # the position is the music's time since paplay began, less paplay's
    # own start-up (measured 0 to 55 ms); the input latency is corrected:
    # the figure leaves [follow] latency out, so play takes the stream's
    err = rec["position"][after] * T - t[after]     # [s]
    assert -0.15 < np.median(err) < 0.05, np.median(err)
    assert np.percentile(err, 95) - np.percentile(err, 5) < 0.06, np.percentile(err, [5, 95])
    assert abs(np.median(rec["rate"][after]) - 1.0) < 0.01


def test_a_server_killed_mid_show_is_reported_recorded_and_exit_1(pulse, music, server_back, tmp_path):
    _, show = music
    flight = tmp_path / "flight.bin"
    proc = play_cli(show, "pulse", 300, record=flight)              # 6 s
    time.sleep(3.5)
    assert proc.poll() is None
    killed = time.monotonic()                       # CLOCK_MONOTONIC, as the records' time [s]
    stop_server()
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 1, (out, err)
    lines = without_status(err)
    # no PortAudio lines, no traceback: the source's line, then the engine's
    # (the music is not followed from the next tick on, on_lost applies)
    assert len(lines) == 2, err
    assert lines[0].startswith("audio input 'pulse' lost: the stream ended by itself"), lines[0]
    assert lines[1].startswith("music not followed from show time "), lines[1]
    assert "on_lost flywheel: the show plays on at the last rate" in lines[1], lines[1]
    assert "Traceback" not in err
    # the show went on to its end, and the summary says what was lost
    assert "real time: 300 ticks" in out, out
    assert "audio input 'pulse':" in out and "LOST: the stream ended by itself" in out, out
    assert "  live source lost at show time " in out, out
    # the flight record says so on every tick from the loss to the end, none before
    _, rec = read_flight_record(flight)
    assert len(rec) == 300
    t = rec["time_ns"] * 1e-9 - killed                                      # [s]
    flagged = (rec["flags"] & FLAG_SOURCE_LOST) != 0
    assert flagged.any(), "the flight record never says the source was lost"
    first = int(np.argmax(flagged))
    assert np.all(flagged[first:]) and np.all(rec["flags"][first:] & FLAG_UNFOLLOWED)
    print(f"source lost flagged {t[first]:.3f} s after the kill ({first} of 300 ticks)")
    assert 0.0 < t[first] < LOST_WITHIN, t[first]


def test_a_silent_source_is_lost_after_half_a_second(pulse, monkeypatch):
    """A server that stops answering (SIGSTOP) delivers no blocks: the
    watchdog, not PortAudio, notices."""
    monkeypatch.setenv("PULSE_SOURCE", f"{SINK}.monitor")
    pid = int(subprocess.run(["pgrep", "-x", "-n", "pulseaudio"], capture_output=True, text=True,
                             check=True).stdout.split()[0])
    lost = []
    source = SoundCard(lambda v: None, device=pulse["index"], on_lost=lost.append).start()
    try:
        deadline = time.monotonic() + 5.0
        while source.frames < 25 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert source.frames >= 25, "no audio before the server was stopped"
        os.kill(pid, signal.SIGSTOP)
        try:
            stopped = time.monotonic()
            while not lost and time.monotonic() < stopped + 3.0:
                time.sleep(0.02)
            noticed = time.monotonic() - stopped                    # [s]
        finally:
            os.kill(pid, signal.SIGCONT)
    finally:
        source.stop()
    assert len(lost) == 1 and lost[0].startswith("no audio for"), lost
    assert source.lost_reason == lost[0]
    assert 0.4 < noticed < 1.0, noticed             # 0.5 s, plus the watchdog's 0.1 s look


def test_devices_by_index_digits_and_name_part(pulse):
    devices = input_devices()
    index = pulse["index"]
    assert _choose(devices, index)["name"] == "pulse"
    assert _choose(devices, str(index))["name"] == "pulse"          # as a command line gives it
    assert _choose(devices, f" {index} ")["name"] == "pulse"
    assert _choose(devices, "PULS")["name"] == "pulse"
    assert _choose(devices, "pulse")["name"] == "pulse"             # equal beats 'contains'
    listed = f"{index}: pulse"
    others = [d for d in devices if "ul" in d["name"].lower()]
    if len(others) > 1:                                             # 'pulse' and 'default'
        with pytest.raises(AudioError, match="ambiguous: .*give the index") as exc:
            _choose(devices, "ul")
        assert listed in str(exc.value)
    with pytest.raises(AudioError, match=f"no audio input device 'no such card' .*{listed}"):
        _choose(devices, "no such card")
    missing = max(d["index"] for d in devices) + 10
    with pytest.raises(AudioError, match=f"no audio input device {missing} .*{listed}"):
        _choose(devices, str(missing))
    with pytest.raises(AudioError, match="give an index or a part of the name"):
        _choose(devices, 1.5)
    # and the source itself, on the real device list
    source = SoundCard(lambda v: None, device=str(index))
    assert source.device["index"] == index and source.name == "pulse"
