"""The live music measured by a servo node: `marionette sim --music` sends
LOUDNESS messages over a pty (serial, or slcan), the host hands their
loudness and bands on (NodeLoudness), and the engine's follower takes the
playback position from them."""
import time
from dataclasses import replace

import numpy as np
import pytest

from hil_support import dance_from_home
from marionette import protocol
from marionette.music.bands import N_BANDS, BandMeter, bands, fit_frames, wav_bands
from marionette.music.feature import LoudnessMeter, read_wav, wav_loudness, write_wav
from marionette.music.node_source import NodeLoudness
from marionette.show import Show
from marionette.sim.music import synthesize
from marionette.transport.can_link import CanLink
from marionette.transport.node_monitor import NodeMonitor
from marionette.transport.serial_link import SerialLink
from test_serial_hil import SIM_PRIORITY, play

TICKS = 400             # 8 s
BAND_TICKS = 100        # SYNCs of the band tests: 2 s


@pytest.mark.xfail(strict=False, reason="flaky: a SYNC that reaches the simulator late makes the "
                   "node measure the wrong audio (2 of 22 runs after the cue refit of 2026-12-02; "
                   "the lock 1-2 ticks off, the first cause, is fixed); docs/music.md, known limits")
@pytest.mark.parametrize("bands", [True, False], ids=["band node", "one-band node"])
def test_follows_music_measured_by_a_node(bands, sim, figure, tmp_path):
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
                loudness=stored, tick_period=figure.tick_period,
                bands=fit_frames(wav_bands(wav), len(stored)))
    trace = tmp_path / "trace.npz"
    # a band node's frames are followed on the bands, a one-band node's on the loudness alone
    s = sim("--serial", "--priority", SIM_PRIORITY, "--music", wav, *(() if bands else ("--loudness-only",)),
            "--trace", trace)
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


def _node_frames(sim, figure, tmp_path, link_kind, *flags):
    """SYNCs every tick period to `marionette sim --music` over link_kind;
    returns what NodeLoudness handed its sink, the simulator's SYNC arrival
    times (model time [s]) and the music as the simulator read it."""
    piece = synthesize("pop", seed=7)
    wav = tmp_path / "music.wav"
    write_wav(wav, piece.samples[:int(4 * piece.sample_rate)], int(piece.sample_rate))
    trace = tmp_path / "trace.npz"
    where = ("--serial",) if link_kind == "serial" else ("--can", "slcan")
    s = sim(*where, "--priority", SIM_PRIORITY, "--music", wav, "--trace", trace, *flags)
    link = (SerialLink(s.ready["serial"]) if link_kind == "serial"
            else CanLink(interface="slcan", channel=s.ready["channel"], bitrate=500000))
    got = []
    source = NodeLoudness(lambda *frame: got.append(frame)).start()
    monitor = NodeMonitor({a.node for a in figure.axes}, on_loudness=source.take)
    link.start_receiving(monitor)
    for k in range(BAND_TICKS):
        link.send(protocol.Sync(k))
        time.sleep(figure.tick_period)
    # the music node (the figure's last) answers the last SYNC with its STATUS, then its LOUDNESS
    last = monitor.nodes[max(monitor.nodes)]
    deadline = time.monotonic() + 5.0                   # on a loaded machine [s]
    while time.monotonic() < deadline and (last.last_tick is None or last.last_tick < BAND_TICKS - 1):
        time.sleep(0.01)
    time.sleep(0.05)
    link.close()
    s.quit()
    return got, np.load(trace)["time"], read_wav(wav)


def _periods(got, sync_times, music, rate, T):
    """Where each frame's period starts in the music [samples], after
    checking that the node answered every SYNC after the first period of
    music with a frame, in order, whose loudness is LoudnessMeter's."""
    meter = LoudnessMeter(rate, T)
    starts = np.floor((sync_times - T) * rate).astype(int)     # [samples]
    starts = starts[(starts >= 0) & (starts + meter.frame_len <= len(music))]
    assert len(got) == len(starts) >= BAND_TICKS - 2, (len(got), len(starts))
    for (value, onset, *_), start in zip(got, starts):
        assert value == pytest.approx(meter.frame_loudness(music[start:start + meter.frame_len])[0],
                                      rel=1e-6, abs=1e-12)          # float32 on the wire
        assert np.isnan(onset)
    assert len({value for value, *_ in got}) > BAND_TICKS // 2      # the music really moved
    return starts + meter.frame_len


@pytest.mark.parametrize("link_kind", ["serial", "slcan"])
def test_a_band_node_sends_the_bands_of_band_meter(sim, figure, tmp_path, link_kind):
    got, sync_times, (music, rate) = _node_frames(sim, figure, tmp_path, link_kind)
    ends = _periods(got, sync_times, music, rate, figure.tick_period)
    window = BandMeter(rate, figure.tick_period).window_len    # [samples]
    worst, compared = 0.0, 0
    for (_, _, levels), end in zip(got, ends):
        assert len(levels) == N_BANDS
        if end < window:
            continue
        want = bands(music[end - window:end], rate)[-1]         # BandMeter on the same audio
        levels = np.array(levels)
        silent = want < 10 ** (-121.25 / 20)                    # below the lowest code
        assert np.all(levels[silent] == 0), (levels, want)
        worst = max(worst, np.max(np.abs(20 * np.log10(levels[~silent] / want[~silent])), initial=0.0))
        compared += 1
    assert compared >= BAND_TICKS - 5 and worst <= 0.25 + 1e-6, (compared, worst)   # half a 0.5 dB step


@pytest.mark.parametrize("link_kind", ["serial", "slcan"])
def test_a_one_band_node_still_sends_its_loudness(sim, figure, tmp_path, link_kind):
    got, sync_times, (music, rate) = _node_frames(sim, figure, tmp_path, link_kind, "--loudness-only")
    _periods(got, sync_times, music, rate, figure.tick_period)
    assert all(len(frame) == 2 for frame in got)                # sink(loudness, onset), as before bands
