"""What the figure does while the music is not followed ([follow] on_lost):
the engine's tick, in step mode, on random decks that lose the place.

Each deck plays a synthesized piece from a random place; for 8 s in the
middle another piece is heard instead (its frames spliced in), and after it
the tape goes on from elsewhere (a jump), so the follower loses the place,
searches and locks again. The follower runs the same in both settings; what
differs is the show's position while it searches."""
import numpy as np
import pytest

from conftest import figure_dict, make_figure
from marionette._core import FLAG_MOVING, FLAG_UNFOLLOWED
from marionette.config import ConfigError, config_from_dict
from marionette.engine import Engine
from marionette.music.feature import loudness
from marionette.music.follower import sync_ticks
from marionette.show import Show
from marionette.sim.music import synthesize
from marionette.sim.tape import Deck, play

T = 0.020           # [s]
SEARCHING = 0       # follow_state code
DECKS = 6


def _decks():
    """(stored loudness, live frames per tick) for DECKS random decks, fixed seeds."""
    rng = np.random.default_rng(20261203)
    out = []
    for i in range(DECKS):
        style = ("pop", "waltz", "techno")[i % 3]
        piece = synthesize(style, seed=int(rng.integers(1000)))
        duration = len(piece.samples) / piece.sample_rate                       # [s]
        jump_at = float(rng.uniform(12.0, 20.0))                                # [s]
        deck = Deck(speed=float(rng.uniform(0.95, 1.05)), wow=0.002, snr_db=30.0, sample_rate=16000,
                    start=float(rng.uniform(0.0, duration / 2)), seconds=40.0,
                    jump=(jump_at, float(rng.uniform(0.0, duration - 30.0))), seed=int(rng.integers(1000)))
        played = play(piece.samples, piece.sample_rate, deck)
        live = sync_ticks(loudness(played.samples, played.sample_rate))[:len(played.truth)]
        other = synthesize(("techno", "ambient", "pop")[i % 3], seed=int(rng.integers(1000)))
        heard = loudness(other.samples, other.sample_rate)[3000:3400]          # 8 s of another piece
        k = int(jump_at / T) - len(heard)
        live[k:k + len(heard)] = heard * 10 ** (rng.uniform(-6.0, 6.0) / 20)   # at another volume
        out.append((style, loudness(piece.samples, piece.sample_rate), live))
    return out


def _run(stored, live, on_lost):
    config = make_figure(1, max_speed=50.0, max_accel=5000.0)
    x = 0.3 * np.sin(2 * np.pi * 0.2 * np.arange(len(stored)) * T)[None]      # [m]
    show = Show(axis_names=config.axis_names, units=["m"], positions=x, loudness=stored, tick_period=T)
    with Engine(config, show, follow="smooth", lead="none", interpolation="linear", record=True,
                follow_start=None,
                on_lost=on_lost) as e:
        for value in live:
            if np.isfinite(value):              # NaN: no frame this tick
                e.push_loudness(float(value))
            e.step(1)
        return e.records()


@pytest.fixture(scope="module")
def runs():
    return [(style, _run(stored, live, "flywheel"), _run(stored, live, "hold"))
            for style, stored, live in _decks()]


def _unfollowed(states):
    """Ticks whose state is searching after some tick had a place."""
    had_place = np.cumsum(states != SEARCHING) > 0
    return had_place & (states == SEARCHING)


def test_the_flag_marks_searching_after_the_first_place(runs):
    lost_decks = 0
    for style, fly, hold in runs:
        # the setting does not change the follower, only the show
        assert np.array_equal(fly["follow_state"], hold["follow_state"]), style
        expected = _unfollowed(fly["follow_state"])
        for r in (fly, hold):
            assert np.array_equal((r["flags"] & FLAG_UNFOLLOWED) != 0, expected), style
        lost_decks += bool(np.any(expected))
        # before the first place (an unknown start) nothing is known: the
        # show stands at the top, rate 0, and is not flagged
        first = np.flatnonzero(fly["follow_state"] != SEARCHING)[0]
        assert first > 0
        for r in (fly, hold):
            assert np.all(r["position"][:first] == 0.0) and np.all(r["rate"][:first] == 0.0)
    assert lost_decks >= DECKS - 1, lost_decks


def _stretches(mask):
    """(first, end) of each run of True."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    return list(zip(edges[::2], edges[1::2]))


def test_hold_stands_where_following_was_lost_and_blends_back(runs):
    held = 0
    for style, _, r in runs:
        lost = (r["flags"] & FLAG_UNFOLLOWED) != 0
        for first, end in _stretches(lost):
            # the position of the last followed tick, rate 0, on every unfollowed tick
            assert np.all(r["position"][first:end] == r["position"][first - 1]), style
            assert np.all(r["rate"][first:end] == 0.0), style
            # followed again: the figure blends to the music's place (an
            # online move), it is not slewed there by the limits
            if end < len(r):
                assert r["flags"][end] & FLAG_MOVING, (style, end)
            held += end - first
    assert held > 500, held


def test_flywheel_plays_on_at_the_last_rate(runs):
    ran = 0
    for style, r, _ in runs:
        lost = (r["flags"] & FLAG_UNFOLLOWED) != 0
        for first, end in _stretches(lost):
            rate = r["rate"][first - 1]                         # the last followed tick's [show ticks per tick]
            assert rate > 0.5, style
            np.testing.assert_allclose(r["rate"][first:end], rate, rtol=0, atol=1e-12)
            steps = np.diff(r["position"][first - 1:end])       # [show ticks per tick]
            np.testing.assert_allclose(steps, rate, rtol=0, atol=1e-6)
            ran += end - first
    assert ran > 500, ran


def test_on_lost_in_the_figure_config():
    d = figure_dict()
    assert config_from_dict(d, "f.toml").follow.on_lost == "flywheel"
    d["follow"] = {"on_lost": "hold"}
    assert config_from_dict(d, "f.toml").follow.on_lost == "hold"
    d["follow"] = {"on_lost": "stop"}
    with pytest.raises(ConfigError, match=r"f.toml: follow.on_lost = 'stop' is not known "
                                          r"\(use one of \('flywheel', 'hold'\)\)"):
        config_from_dict(d, "f.toml")
    config = make_figure(1)
    show = Show(axis_names=config.axis_names, units=["m"], positions=np.zeros((1, 50)),
                loudness=np.ones(50), tick_period=T)
    with pytest.raises(ValueError, match="on_lost must be one of"):
        Engine(config, show, follow="smooth", on_lost="stop")
