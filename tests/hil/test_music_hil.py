"""The live music's loudness measured by a servo node: `marionette sim
--music` sends LOUDNESS messages over the pty, and the engine's follower
takes the playback position from them."""
from dataclasses import replace

import numpy as np
import pytest

from hil_support import dance_from_home
from marionette.music.feature import wav_loudness, write_wav
from marionette.show import Show
from marionette.sim.music import synthesize
from marionette.transport.serial_link import SerialLink
from test_serial_hil import SIM_PRIORITY, play

TICKS = 400             # 8 s


@pytest.mark.xfail(strict=False, reason="flaky: a SYNC that reaches the simulator late makes the "
                   "node measure the wrong audio (2 of 22 runs after the cue refit of 2026-12-02; "
                   "the lock 1-2 ticks off, the first cause, is fixed); docs/music.md, known limits")
def test_follows_music_measured_by_a_node(sim, figure, tmp_path):
    # the node measures the tick period before each SYNC and answers with
    # it; the engine takes it at the next tick, one period after that
    # audio ended: the [follow] latency says so
    figure = replace(figure, follow=replace(figure.follow, latency=figure.tick_period))
    piece = synthesize("pop", seed=5)
    wav = tmp_path / "music.wav"
    write_wav(wav, piece.samples, int(piece.sample_rate))
    stored = wav_loudness(wav)
    dance = dance_from_home(figure, len(stored) * figure.tick_period, seed=10)
    show = Show(axis_names=dance.axis_names, units=dance.units, positions=dance.positions,
                loudness=stored, tick_period=figure.tick_period)
    trace = tmp_path / "trace.npz"
    s = sim("--serial", "--priority", SIM_PRIORITY, "--music", wav, "--trace", trace)
    link = SerialLink(s.ready["serial"])
    records, nodes, _, _ = play(figure, show, link, ticks=TICKS, follow="smooth")
    link.close()
    s.quit()
    t0 = float(np.load(trace)["t0"])
    # frames came in: live_loudness is NaN on a tick without a new frame, and
    # a node's answer may come a tick late (then two come in the next)
    fresh = np.isfinite(records["live_loudness"][10:])
    assert np.mean(fresh) >= 0.8, np.mean(fresh)
    assert not np.any(np.convolve(~fresh, np.ones(5), "valid") == 5)    # never 5 ticks without
    # where the music is at each tick: it started with the simulator's clock
    truth = (records["time_ns"] * 1e-9 - t0) / figure.tick_period     # [ticks]
    locked = records["follow_state"] == 1
    late = np.arange(TICKS) >= 250
    assert np.mean(locked[late]) > 0.9, np.mean(locked[late])
    err = np.abs(records["position"] - truth)[locked & late]
    # within 10 ms at the median and 20 ms always: the frames' age is fixed
    # (a latency off by one tick shows here)
    assert np.median(err) <= 0.5 and err.max() <= 1.0, (np.median(err), err.max())
