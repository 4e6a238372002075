"""The engine with the music follower in its tick: the live loudness drives
the playback position, and in smooth mode the motion has no doubled or
skipped samples (the paper's mode does double and skip, as it should)."""
import numpy as np
import pytest

from conftest import make_figure
from marionette.bench.music import synthesize
from marionette.bench.tape import Deck, play
from marionette._core import FLAG_MOVING
from marionette.engine import Engine
from marionette.follow import FollowError, sync_ticks
from marionette.loudness import loudness
from marionette.show import Show

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
    with Engine(config, show, follow=mode, lead="none", interpolation="linear", record=True) as e:
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
        # and the commands are the show sampled there
        expected = np.interp(r["position"][after], np.arange(show.n_ticks), show.positions[0])
        np.testing.assert_allclose(r["command"][after, 0], expected, atol=1e-9)
    else:
        assert set(np.unique(steps)) <= {0.0, 1.0, 2.0} and 2.0 in steps
    assert np.all(np.isfinite(r["follow_confidence"]))
    # the lock is a jump of the position: the figure gets there by a timed
    # blend (online moves), then plays
    lock = np.flatnonzero(locked)[0]
    assert r["flags"][lock] & FLAG_MOVING and not np.any(r["flags"][after] & FLAG_MOVING)


def test_following_needs_the_stored_loudness():
    config = make_figure(1)
    silent = Show(axis_names=config.axis_names, units=["m"], positions=np.zeros((1, 50)),
                  loudness=np.zeros(50), tick_period=T)
    with pytest.raises(FollowError, match="silent"):
        Engine(config, silent, follow="smooth")
    with Engine(config, silent) as e:            # without a follower: no record fields set
        e.step(2)
        assert e.snapshot().follow_state is None
