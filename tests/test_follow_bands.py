"""The follower on band levels (marionette/music/bands.py, ext/mar_follow.c):
a show that stores them is followed on them wherever the live frames bring
as many, on the loudness where they do not (a one-band node), and the
bands place a cue in a reverberant room sooner than the loudness alone.

Live audio is synthesized music through the simulated tape deck, whose
time warp is the truth; fixed seeds, several decks each."""
from __future__ import annotations

import math

import numpy as np
import pytest

from marionette.bench import sync
from marionette.music.follower import STATES, FollowError, Follower
from marionette.sim.tape import Deck
from taught_music import taught

T = 0.020                                            # tick [s]
LOCKED = STATES.index("locked")
MEDIAN_LOCK_S = 0.5             # the median right cue's lock, at most [s] (measured 0.40; 0.80 before)
LAST_LOCK_S = 0.8               # the last right cue's lock, at most [s] (measured 0.6; 0.9 before)
WRONG_LATER_S = 0.5             # a wrong cue's place found this much later than from an unknown start,
                                # at most [s] (measured 0.00; 0.78 before the search ran on beside the cue)


def live_frames(piece, deck):
    """The deck's recording as the tick hears it (as bench sync plays it):
    loudness, onsets, band levels, truth [s]."""
    played, (loud, live_onsets, rows) = sync.live_frames(piece, deck)
    return loud, live_onsets, rows, played.truth


def cued_run(style, seed, deck, use_bands, live_bands=True, cue=0.0):
    piece, loud, ons, rows = taught(style, seed)
    live, live_onsets, live_rows, truth = live_frames(piece, deck)
    f = Follower(loud, onset=ons, bands=rows if use_bands else None)
    f.cue(cue)                                       # [stored ticks], None: unknown
    track = f.run(live, live_onsets, bands=live_rows if live_bands else None)
    return track, track.position * T - truth


def first_lock(track, err, within=0.05):
    """Live time [s] of the first tick LOCKED within `within` [s] of the truth."""
    idx = np.flatnonzero((track.state == LOCKED) & (np.abs(err) <= within))
    return idx[0] * T if len(idx) else math.inf


def lock_entries(track):
    """Ticks at which the follower entered LOCKED (from any other state)."""
    before = np.concatenate([[-1], track.state[:-1]])
    return np.flatnonzero((track.state == LOCKED) & (before != LOCKED))


def room(seed, speed):
    """A tape from the top in a reverberant room (RT60 0.5 s, 20 dB SNR), 25 s."""
    return Deck(speed=speed, wow=0.002, snr_db=20.0, reverb_s=0.5, sample_rate=16000, seconds=25.0, seed=seed)


def test_frames_without_bands_are_followed_on_the_loudness_bit_for_bit():
    """A show with bands, live frames without (a one-band node): the very
    track of the same show without bands."""
    for seed, speed in ((1, 0.96), (2, 1.04)):
        with_bands, _ = cued_run("pop", 1, room(seed, speed), True, live_bands=False)
        without, _ = cued_run("pop", 1, room(seed, speed), False)
        for key in ("position", "rate", "confidence", "state", "flags"):
            np.testing.assert_array_equal(getattr(with_bands, key), getattr(without, key))


def test_bands_place_a_cue_in_a_room_sooner_than_the_loudness():
    """Cued at the top, 8 decks in a reverberant room at 0.95-1.05 speed:
    with bands the median deck locks within 50 ms of the truth by 2 s of
    music (measured 1.6 s), sooner than on the loudness alone (4.2 s), no
    lock is entered more than 0.5 s off, and 95 % of the ticks from 1 s on
    are within 50 ms. (One
    deck, ambient at 1.027, does not lock in its 25 s: its cue fits never
    lead the piece clearly enough, and the tracker, which follows it,
    never locks a pending cue on its own: docs/music.md.)"""
    rng = np.random.default_rng(20261202)
    locks = {True: [], False: []}
    within50 = []
    for case in range(8):
        style, seed = (("pop", 1), ("waltz", 2), ("techno", 4), ("ambient", 3))[case % 4]
        deck = room(int(rng.integers(1000)), float(rng.uniform(0.95, 1.05)))
        for use_bands in (True, False):
            track, err = cued_run(style, seed, deck, use_bands)
            locks[use_bands].append(first_lock(track, err))
            if use_bands:
                entries = lock_entries(track)
                assert np.all(np.abs(err[entries]) <= 0.5), (case, err[entries])
                within50.append(np.abs(err[int(1.0 / T):]) <= 0.05)
    assert np.median(locks[True]) <= 2.0, locks[True]
    assert np.median(locks[True]) < np.median(locks[False]), locks
    assert np.mean(np.concatenate(within50)) >= 0.95, [np.mean(w) for w in within50]


def hissy_tape(seed, speed, start):
    """A tape at 20 dB SNR with a little wow, 25 s from `start` [s]."""
    return Deck(speed=speed, wow=0.002, snr_db=20.0, sample_rate=11025, start=start, seconds=25.0, seed=seed)


def test_with_bands_a_right_cue_locks_sooner_and_a_wrong_one_never():
    """Cued at the top: 16 random decks at 0.94-1.06 from the top, and 8
    started 10-60 s in (the cue wrong). With bands a cue's line locks
    unless another place leads it (docs/music.md): the median
    right cue is LOCKED within 50 ms by MEDIAN_LOCK_S of music and every
    one by LAST_LOCK_S, and no deck enters LOCKED more than 0.5 s off."""
    rng = np.random.default_rng(20261205)
    styles = (("pop", 1), ("waltz", 2), ("techno", 4), ("ambient", 3))
    locks = []
    for case in range(24):
        style, seed = styles[case % 4]
        wrong = case >= 16
        deck = hissy_tape(int(rng.integers(1000)), float(rng.uniform(0.94, 1.06)),
                          float(rng.uniform(10.0, 60.0)) if wrong else 0.0)
        track, err = cued_run(style, seed, deck, use_bands=True)
        entries = lock_entries(track)
        assert np.all(np.abs(err[entries]) <= 0.5), (case, style, err[entries])
        if not wrong:
            locks.append(first_lock(track, err))
    assert np.median(locks) <= MEDIAN_LOCK_S, sorted(locks)
    assert max(locks) <= LAST_LOCK_S, sorted(locks)


def test_with_bands_a_wrong_cue_is_found_as_fast_as_from_an_unknown_start():
    """12 random tapes started 10-60 s in, cued at the top and run again
    from an unknown start: the cued run is LOCKED within 50 ms of the truth
    at most WRONG_LATER_S later (the search beside a pending cue listens
    from the onset, as the unknown start's does from the first frame)."""
    rng = np.random.default_rng(20261207)
    styles = (("pop", 1), ("waltz", 2), ("techno", 4), ("ambient", 3))
    for case in range(12):
        style, seed = styles[case % 4]
        deck = hissy_tape(int(rng.integers(1000)), float(rng.uniform(0.94, 1.06)), float(rng.uniform(10.0, 60.0)))
        cued_s, unknown_s = (first_lock(*cued_run(style, seed, deck, True, cue=cue)) for cue in (0.0, None))
        assert cued_s <= unknown_s + WRONG_LATER_S, (case, style, cued_s, unknown_s)


def test_a_stop_under_the_hiss_is_not_flown_through():
    """The volume is turned 20 dB down (the music then stands at the 20 dB
    SNR hiss) and 2.5-4 s later the tape stops for 6-10 s: a stop that the
    level may not show until the music expected rises again, by when the
    place may be lost. By the stop's last 2 s the place is held within
    0.25 s of where the tape stopped, and mostly back within 50 ms from 1 s
    after the restart. Twenty random cued decks, five per style. Before a
    second of hiss while searching a lost place was taken for a stop there,
    two of them flew through it (6.8 and 9.2 s ahead at its end)."""
    rng = np.random.default_rng(5)
    held, back, valid = [], 0, 0
    for style, seed in (("pop", 1), ("waltz", 2), ("techno", 4), ("ambient", 3)):
        for case in range(5):
            turn = float(rng.uniform(10.0, 20.0))                                 # [s]
            stop, length = turn + float(rng.uniform(2.5, 4.0)), float(rng.uniform(6.0, 10.0))    # [s]
            deck = Deck(speed=float(rng.uniform(0.95, 1.06)), wow=0.001, wow_hz=0.9, snr_db=20.0,
                        sample_rate=11025, gain_db=((0.0, 0.0), (turn, 0.0), (turn + 2.0, -20.0)),
                        pauses=((stop, length),), seconds=stop + length + 8.0, seed=int(rng.integers(1000)))
            _, err = cued_run(style, seed, deck, use_bands=True)
            err = np.abs(err)
            t = np.arange(len(err)) * T
            if err[int((turn - 0.1) / T)] > 0.05:
                continue                                      # not on the place before the turn
            valid += 1
            held.append(np.max(err[(t > stop + length - 2.0) & (t < stop + length)]))
            back += np.mean(err[t >= stop + length + 1.0] <= 0.05) >= 0.95
    assert valid >= 16
    assert max(held) <= 0.25, np.round(held, 2)
    assert back >= valid - 5                                  # before: 14 of 20


def test_bad_bands_are_refused():
    piece, loud, ons, rows = taught("pop", 1)
    bad = rows.copy()
    bad[10, 2] = -1.0
    with pytest.raises(FollowError, match=r"stored bands\[10, 2\] = -1.0"):
        Follower(loud, bands=bad)
    with pytest.raises(FollowError, match="shape"):
        Follower(loud, bands=rows[:-1])
    with pytest.raises(FollowError, match="shape"):
        Follower(loud, bands=np.ones((len(loud), 9)))
    f = Follower(loud, bands=rows)
    out = f.step(0.1, bands=[0.1, 0.2, -0.3, 0.1, 0.1, 0.1])     # refused as a source would be
    assert out.flags & 1 and f.counters()["bad_input"] == 1


def test_a_jump_into_resembling_music_is_doubted_soon():
    """Cued at the top, six random tapes (0.94-1.06) jump at 27.75 s from
    26-29 s in the pop piece back to 6.8 s, into music much like where they
    were (bench sync's pop/jump@20261124 from the top): the tracking fit
    falls slowly over its window. The long-run fit it is compared with
    learns from the usual fit only, not from the collapse, and the doubt's
    search hears the music from where the fit began to fall: LOCKED at the
    old place for at most 1.2 s on every tape (measured 0.70-0.88 s; 1.30-1.76 s
    when the long run followed the collapse down), the new place LOCKED
    within 50 ms by 6.5 s after the jump on the median tape (5.6 s; 7.3 s),
    and no lock entered off the truth."""
    rng = np.random.default_rng(20261208)
    jump_s = 27.751645645240387                                    # [s] live time
    relocks = []
    for case in range(6):
        deck = Deck(speed=float(rng.uniform(0.94, 1.06)), wow=0.005, wow_hz=1.0, flutter=0.002, flutter_hz=10.0,
                    snr_db=30.0, reverb_s=0.3, jump=(jump_s, 6.82130682766969), sample_rate=22050, seconds=40.0,
                    seed=int(rng.integers(1000)))
        track, err = cued_run("pop", 1, deck, use_bands=True)
        t = np.arange(len(err)) * T
        locked = track.state == LOCKED
        entries = lock_entries(track)
        assert np.all(np.abs(err[entries]) <= 0.2), (case, err[entries])
        wrong_s = np.sum(locked & (np.abs(err) > 0.2) & (t > jump_s)) * T
        assert wrong_s <= 1.2, (case, wrong_s)
        relock = np.flatnonzero(locked & (np.abs(err) <= 0.05) & (t > jump_s + 0.2))
        relocks.append(t[relock[0]] - jump_s if len(relock) else math.inf)
    assert np.median(relocks) <= 6.5, np.round(relocks, 2)
