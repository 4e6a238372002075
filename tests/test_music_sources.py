"""The live sources of music (marionette.music.source): a recording played
as if live, and the servo nodes' LOUDNESS."""
import time

import numpy as np
import pytest

from marionette.errors import EngineError
from marionette.music.feature import wav_frames, write_wav
from marionette.music.follower import sync_ticks
from marionette.music.node_source import NodeLoudness
from marionette.music.sound_card import SoundCard
from marionette.music.source import LiveSource
from marionette.music.wav_source import WavSource

RATE = 8000                     # [Hz]


@pytest.fixture
def recording(tmp_path):
    """A 0.5 s recording: a tone that swells, 25 frames of 20 ms."""
    t = np.arange(int(0.5 * RATE)) / RATE                               # [s]
    path = tmp_path / "live.wav"
    write_wav(path, 0.5 * t * np.sin(2 * np.pi * 440.0 * t), RATE)
    return path


def test_every_source_is_a_live_source():
    for kind in (SoundCard, WavSource, NodeLoudness):
        assert issubclass(kind, LiveSource)


def test_a_recording_in_step_mode_gives_tick_k_frame_k_minus_1(recording):
    got = []
    source = WavSource(recording, lambda v, o: got.append((v, o)))
    loud, onset = wav_frames(recording)
    assert len(loud) == 25 and source.name == str(recording) and source.latency is None
    for k in range(30):                                                 # [ticks], past its end
        before = len(got)
        source.feed_tick(k)
        assert len(got) - before == (1 if 1 <= k <= 25 else 0)
    assert np.array_equal([v for v, _ in got], sync_ticks(loud)[1:])
    assert np.array_equal([o for _, o in got], sync_ticks(onset)[1:])
    assert source.frames == 25


def test_a_recording_in_real_time_gives_one_frame_per_period(recording):
    got = []
    with WavSource(recording, lambda v, o: got.append((time.monotonic(), v, o))) as source:
        deadline = time.monotonic() + 5.0                               # [s]
        while source.frames < 25 and time.monotonic() < deadline:
            time.sleep(0.01)
    loud, onset = wav_frames(recording)
    assert source.frames == len(got) == 25
    assert np.array_equal([v for _, v, _ in got], loud) and np.array_equal([o for _, _, o in got], onset)
    assert got[-1][0] - got[0][0] >= 24 * 0.020 * 0.9                   # paced, not all at once [s]


def test_a_stopped_recording_gives_no_more_frames(recording):
    got = []
    source = WavSource(recording, lambda v, o: got.append(v), period=0.05).start()
    source.stop()
    n = len(got)
    time.sleep(0.12)
    assert len(got) == n < 25


def test_node_loudness_goes_to_the_sink_while_open_and_counts_refusals():
    got = []

    def sink(value, onset):
        if value < 0:
            raise ValueError("negative")
        if value > 100:
            raise EngineError("full ring")
        got.append((value, onset))

    source = NodeLoudness(sink)
    source.take(0.5)                                        # not started: dropped
    source.start()
    source.take(0.25)
    source.take(-1.0)
    source.take(1000.0)
    source.stop()
    source.take(0.75)                                       # stopped: dropped
    assert got[0][0] == 0.25 and np.isnan(got[0][1]) and len(got) == 1
    assert source.frames == 1 and source.refused == 2 and source.latency is None


def test_node_loudness_hands_bands_on_and_a_one_band_frame_as_two_values():
    got = []
    source = NodeLoudness(lambda *frame: got.append(frame)).start()
    source.take(0.5, (0.1, 0.2, 0.0))
    source.take(0.25)
    source.take(0.125, None)
    assert [len(f) for f in got] == [3, 2, 2]
    assert got[0][0] == 0.5 and np.isnan(got[0][1]) and got[0][2] == (0.1, 0.2, 0.0)
    assert source.frames == 3


class _Link:
    """A link that keeps what the tick writes and hands the test the node monitor."""

    protocol = "serial"

    def __init__(self):
        self.monitor = None

    def write(self, data):
        return len(data)

    def start_receiving(self, monitor):
        self.monitor = monitor


def test_the_engine_hears_the_nodes_loudness_while_it_follows():
    from marionette import protocol
    from marionette.engine import Engine

    from conftest import make_figure, make_show

    config = make_figure()
    t = np.arange(200) * config.tick_period                             # [s]
    show = make_show(config, np.zeros((3, 200)), loudness=1.0 + np.sin(2 * np.pi * t))
    link = _Link()
    with Engine(config, show, output=link, follow=True, record=True) as engine:
        link.monitor.take(protocol.Loudness(1, 1, 0.5))
        link.monitor.take(protocol.Loudness(1, 2, -1.0))                # refused by the engine
        engine.step(2)
        assert engine.node_loudness.frames == 1 and engine.node_loudness.refused == 1
        assert engine.records()["live_loudness"][0] == 0.5
    link.monitor.take(protocol.Loudness(1, 3, 0.25))                    # closed: dropped
    assert engine.node_loudness.frames == 1
