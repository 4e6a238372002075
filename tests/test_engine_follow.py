"""The engine with the music follower in its tick: the live loudness drives
the playback position, and in smooth mode the motion has no doubled or
skipped samples (the paper's mode does double and skip, as it should)."""
import numpy as np
import pytest

from conftest import make_figure
from marionette._core import FLAG_MOVING
from marionette.engine import Engine
from marionette.music.feature import loudness, onsets
from marionette.music.follower import Follower, FollowError, sync_ticks
from marionette.show import Show
from marionette.sim.music import synthesize
from marionette.sim.tape import Deck, play

T = 0.020


@pytest.fixture(scope="module")
def taught():
    piece = synthesize("pop", seed=3)
    stored = loudness(piece.samples, piece.sample_rate)
    deck = Deck(speed=1.03, wow=0.002, snr_db=30.0, sample_rate=22050, seed=4)
    played = play(piece.samples, piece.sample_rate, deck)
    live = sync_ticks(loudness(played.samples, played.sample_rate))[:len(played.truth)]
    return stored, live, played.truth


def show_for(config, stored):
    """A slow sine on each axis, taught with the music's loudness."""
    n = len(stored)
    t = np.arange(n) * T
    x = np.array([0.3 * np.sin(2 * np.pi * (0.2 + 0.05 * j) * t) for j in range(len(config.axes))])
    return Show(axis_names=config.axis_names, units=[a.unit for a in config.axes], positions=x,
                loudness=stored, tick_period=T)


def run(config, show, live, mode):
    """An unknown start: the first lock is a jump of the position (a cue at
    the top is tests/test_cue.py's)."""
    with Engine(config, show, follow=mode, lead="none", interpolation="linear", record=True,
                follow_start=None) as e:
        for value in live:
            if np.isfinite(value):              # NaN: no frame came this tick
                e.push_loudness(float(value))
            e.step(1)
        return e.records()


@pytest.mark.parametrize("mode", ["smooth", "paper"])
def test_the_music_drives_the_show(taught, mode):
    stored, live, truth = taught
    config = make_figure(2, max_speed=50.0, max_accel=5000.0)
    show = show_for(config, stored)
    r = run(config, show, live, mode)
    locked = r["follow_state"] == 1
    assert np.mean(locked[250:]) > 0.9, np.mean(locked)
    after = np.flatnonzero(locked)[np.flatnonzero(locked) > 300]
    # the playback position is where the tape is in the taught music
    err = r["position"][after] * T - truth[after]                     # [s]
    assert np.mean(np.abs(err) <= (0.020 if mode == "smooth" else 0.050)) >= 0.9, np.abs(err).max()
    steps = np.diff(r["position"])[after[:-1]]
    if mode == "smooth":
        # fractional steps near the tape's speed: never a doubled (0) or skipped (2) sample
        assert np.all((steps > 0.9) & (steps < 1.2)), (steps.min(), steps.max())
        assert abs(np.median(steps) - 1.03) < 0.005
        # and the commands are the show sampled there, at the engine's clock,
        # which follows the music's corrections smoothly (ext/mar_clock.h):
        # within a third of a tick (7 ms; 0.22 tick here), mostly within 0.05
        expected = np.interp(r["position"][after], np.arange(show.n_ticks), show.positions[0])
        slope = np.abs(np.diff(show.positions[0])).max()                 # [unit/tick]
        off = np.abs(r["command"][after, 0] - expected) / slope             # [ticks], at least
        assert off.max() < 0.33 and np.median(off) < 0.05, (off.max(), np.median(off))
    else:
        assert set(np.unique(steps)) <= {0.0, 1.0, 2.0} and 2.0 in steps
    assert np.all(np.isfinite(r["follow_confidence"]))
    # the lock is a jump of the position: the figure gets there by a timed
    # blend (online moves), then plays
    lock = np.flatnonzero(locked)[0]
    assert r["flags"][lock] & FLAG_MOVING and not np.any(r["flags"][after] & FLAG_MOVING)


def test_the_engine_follows_with_onsets_as_sync_sim_does():
    """A show taught with onsets: the engine's follower, fed loudness and
    onset per tick, gives the positions of Follower(..., onset=...) (what
    sync-sim runs) tick for tick; a frame without its onset (a node's
    LOUDNESS) is taken, and the tracker falls back to the loudness."""
    piece = synthesize("ambient", seed=3)
    stored, stored_onsets = loudness(piece.samples, piece.sample_rate), onsets(piece.samples, piece.sample_rate)
    deck = Deck(speed=0.97, wow=0.003, reverb_s=0.5, snr_db=20.0, sample_rate=16000, start=30.0,
                seconds=30.0, seed=5)
    played = play(piece.samples, piece.sample_rate, deck)
    live = sync_ticks(loudness(played.samples, played.sample_rate))[:len(played.truth)]
    live_onsets = sync_ticks(onsets(played.samples, played.sample_rate))[:len(played.truth)]
    rng = np.random.default_rng(8)
    live_onsets[rng.random(len(live_onsets)) < 0.05] = np.nan          # some frames without
    config = make_figure(1, max_speed=50.0, max_accel=5000.0)
    show = show_for(config, stored)
    show.onsets = stored_onsets
    with Engine(config, show, follow="smooth", lead="none", interpolation="linear", record=True,
                follow_start=None) as e:
        for value, onset in zip(live, live_onsets):
            if np.isfinite(value):
                e.push_loudness(float(value), float(onset))
            e.step(1)
        r = e.records()
    # tick 0 has no frame (the engine does not step its follower there)
    reference = Follower(stored, onset=stored_onsets).run(live[1:], live_onsets[1:])
    np.testing.assert_allclose(r["position"][1:], reference.position, rtol=0, atol=1e-9)
    assert np.array_equal(r["follow_state"][1:], reference.state)
    without = Follower(stored).run(live[1:])
    assert not np.allclose(without.position, reference.position)      # the onsets did count
    with Engine(config, show, follow="smooth") as e, pytest.raises(ValueError, match="onset -1.0"):
        e.push_loudness(0.5, -1.0)


def test_following_needs_the_stored_loudness():
    config = make_figure(1)
    silent = Show(axis_names=config.axis_names, units=["m"], positions=np.zeros((1, 50)),
                  loudness=np.zeros(50), tick_period=T)
    with pytest.raises(FollowError, match="silent"):
        Engine(config, silent, follow="smooth")
    with Engine(config, silent) as e:            # without a follower: no record fields set
        e.step(2)
        assert e.snapshot().follow_state is None
