"""The follower's tape deck model (mode "model", ext/mar_follow_deck.h):
the smooth mode's tracker and search, decided by two beliefs (the deck
plays or stands still; which place the music comes from) instead of rules.
Scenario tests on synthesized music through the simulated tape deck, whose
time warp is the truth; fixed seeds, several decks each. The beliefs'
update itself is unit-tested in C (ext/tests/test_follow.c)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from marionette.music.bands import bands, fit_frames
from marionette.music.feature import loudness, onsets
from marionette.music.follower import STATES, Follower, sync_ticks
from marionette.sim.tape import Deck, play
from taught_music import taught

T = 0.020                                            # tick [s]
LOCKED, PAUSED = STATES.index("locked"), STATES.index("paused")


def run(style, seed, deck, cue=None, use_bands=True):
    """The model followed the deck's recording: (track, error [s], played)."""
    piece, loud, ons, rows = taught(style, seed)
    played = play(piece.samples, piece.sample_rate, deck)
    n = len(played.truth)
    live = sync_ticks(loudness(played.samples, played.sample_rate))[:n]
    live_rows = sync_ticks(fit_frames(bands(played.samples, played.sample_rate), len(live) - 1))
    f = Follower(loud, onset=ons, bands=rows if use_bands else None, mode="model")
    if cue is not None:
        f.cue(cue)
    track = f.run(live, sync_ticks(onsets(played.samples, played.sample_rate))[:n],
                  bands=live_rows if use_bands else None)
    return track, track.position[:n] * T - played.truth, played


def first(cond, after=0.0):
    """Live time [s] from `after` to the first tick where cond holds (inf: never)."""
    idx = np.flatnonzero(cond & (np.arange(len(cond)) * T >= after))
    return idx[0] * T - after if len(idx) else math.inf


def false_locks(track, err):
    """Entries into LOCKED more than 0.5 s off the truth."""
    state = track.state[:len(err)]
    entered = np.flatnonzero((state == LOCKED) & (np.concatenate([[-1], state[:-1]]) != LOCKED))
    return int(np.sum(np.abs(err[entered]) > 0.5))


def deck(seed, speed, **kw):
    """25 s of tape in a reverberant room (RT60 0.3 s) with hiss 25 dB under the music."""
    args = dict(speed=speed, wow=0.002, wow_hz=0.7, snr_db=25.0, reverb_s=0.3, sample_rate=16000,
                seconds=25.0, seed=seed)
    args.update(kw)
    return Deck(**args)


DECKS = [(style, piece_seed, seed, speed) for style, piece_seed in (("pop", 1), ("waltz", 2), ("techno", 4))
         for seed, speed in ((11, 0.95), (12, 1.05))]


@pytest.mark.parametrize("style,piece_seed,seed,speed", DECKS)
def test_the_model_follows_from_the_cue_and_from_anywhere(style, piece_seed, seed, speed):
    """From the top cued at 0, and 30 s in from an unknown start: LOCKED
    within 50 ms of the truth within 3 s (a cue waits for the search to
    have looked around the piece), 95 % of the ticks from then on within
    50 ms, and no lock entered more than 0.5 s off."""
    for cue, start in ((0.0, 0.0), (None, 30.0)):
        track, err, _ = run(style, piece_seed, deck(seed, speed, start=start), cue=cue)
        lock = first((track.state[:len(err)] == LOCKED) & (np.abs(err) <= 0.05))
        assert lock <= 3.0, f"{style} at {speed}, cue {cue}: locked after {lock:.2f} s"
        after = np.abs(err[int(round(lock / T)):])
        assert np.mean(after <= 0.05) >= 0.95, f"{style} at {speed}, cue {cue}: {np.mean(after <= 0.05):.1%}"
        assert false_locks(track, err) == 0


# On 40 random decks of each kind (docs/music.md, "Each band on its own")
# the prototype failed 10 stops and 27 jumps with the joint correlation,
# 14 and 19 with the per-band one, which turned these two seeds.
PER_BAND = "since the per-band correlation (docs/music.md, 'Each band on its own'): "


@pytest.mark.parametrize("seed", [21, pytest.param(22, marks=pytest.mark.xfail(
    strict=True, reason=PER_BAND + "the followed place's window fits 0.93 against its usual 0.97 for 0.7 s "
                        "before the stop, the place belief falls under 0.5 and the motion belief is not asked")),
    23, 24])
def test_a_stop_is_paused_and_the_music_back_resumes_it(seed):
    """A tape stopped 8-12 s in for 2-5 s: PAUSED within 0.5 s of the stop,
    and within 50 ms of the truth (not PAUSED) 0.5 s after the restart
    (issue 21's target)."""
    rng = np.random.default_rng(seed)
    at, length = float(rng.uniform(8.0, 12.0)), float(rng.uniform(2.0, 5.0))      # [s] live
    track, err, played = run("pop", 1, deck(seed, float(rng.uniform(0.95, 1.05)), start=20.0,
                                            pauses=((at, length),)), cue=None)
    state = track.state[:len(err)]
    assert first(state == PAUSED, at) <= 0.5, f"seed {seed}: the stop at {at:.2f} s not seen"
    resume = played.resumes[0]
    back = first((np.abs(err) <= 0.05) & (state != PAUSED), resume)
    assert back <= 0.5, f"seed {seed}: {back:.2f} s after the restart at {resume:.2f} s"


@pytest.mark.parametrize("seed", [31, pytest.param(32, marks=pytest.mark.xfail(
    strict=True, reason=PER_BAND + "the first lock, 2.5 s after an unknown start, takes a repeat 34 s off; "
                        "the right place takes over 2.7 s later")), 33])
def test_a_jump_elsewhere_takes_over_from_the_followed_place(seed):
    """The tape jumps 10 s in to a place 40-80 s away: the place the music
    comes from takes over (LOCKED within 50 ms of the truth), and no lock
    is entered more than 0.5 s off. The model needs about a window (4 s)
    for the evidence against the followed place, then a whole sweep for
    the new place to prove itself: within 8 s (measured 3.2-6.8 s)."""
    rng = np.random.default_rng(seed)
    to = float(rng.uniform(60.0, 100.0))                                          # [s] taught
    track, err, played = run("pop", 1, deck(seed, 1.0 + float(rng.uniform(-0.04, 0.04)), start=20.0,
                                            jump=(10.0, to)), cue=None)
    jump = played.jumps[0]
    back = first((track.state[:len(err)] == LOCKED) & (np.abs(err) <= 0.05), jump)
    assert back <= 8.0, f"seed {seed}: {back:.2f} s after the jump to {to:.1f} s"
    assert false_locks(track, err) == 0


def test_a_one_band_show_is_followed_on_its_loudness():
    """A show without band levels (an older one) follows with the model too."""
    track, err, _ = run("pop", 1, deck(41, 1.03, start=30.0), cue=None, use_bands=False)
    lock = first((track.state[:len(err)] == LOCKED) & (np.abs(err) <= 0.05))
    assert lock <= 5.0
    assert np.mean(np.abs(err[int(round(lock / T)):]) <= 0.05) >= 0.95
    assert false_locks(track, err) == 0
