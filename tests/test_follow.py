"""The music follower (ext/mar_follow.c through marionette.music.follower): it locks
and follows a fast tape, holds through a pause, finds an unknown start,
stays put on silence and noise, and refuses bad input without noticing it.
The C code also runs standalone under AddressSanitizer and UBSan, with
allocation counting around the steps.

Live audio is synthesized music (marionette.sim.music) played through the
simulated tape deck (marionette.sim.tape), whose time warp is the truth.
Positions are compared in seconds of taught music; no timing assertions.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from marionette.config import FollowConfig, config_from_dict
from marionette.errors import ConfigError
from marionette.music.feature import loudness, mono, onsets, read_wav
from marionette.music.follower import (FLAGS, OPTIONS, STATES, FollowError, Follower, c_options,
                                       options_markdown, sync_ticks)
from marionette.sim.music import synthesize
from marionette.sim.tape import Deck, play
from marionette.teach.make_sample import sample_path
from conftest import FOLLOW_CFLAGS, figure_dict

ROOT = Path(__file__).resolve().parents[1]
T = 0.020                                            # tick [s]
LOCKED, HOLDING, PAUSED = (STATES.index(s) for s in ("locked", "holding", "paused"))
FOUR_STYLES = (("pop", 1), ("waltz", 2), ("techno", 4), ("ambient", 3))    # (style, seed) of the pieces


@pytest.fixture(scope="module")
def piece():
    return synthesize("pop", seed=1)


@pytest.fixture(scope="module")
def stored(piece):
    return loudness(piece.samples, piece.sample_rate)


def live_track(piece, stored, deck, mode="smooth", start=None):
    """Runs the follower over the deck's recording; (track, played, error [s] per tick)."""
    played = play(piece.samples, piece.sample_rate, deck)
    live = sync_ticks(loudness(played.samples, played.sample_rate))[:len(played.truth)]
    f = Follower(stored, mode=mode)
    if start is not None:
        f.reset(start)
    track = f.run(live)
    return track, played, track.position * T - played.truth, f


def first_lock(track, err, after=0.0, within=0.05):
    """Live time [s] of the first tick LOCKED within `within` [s] of the truth, from after [s]."""
    t = np.arange(len(err)) * T
    idx = np.flatnonzero((track.state == LOCKED) & (np.abs(err) <= within) & (t >= after))
    return t[idx[0]] if len(idx) else math.inf


def stop_caught(track, err, stop, pause, held_from):
    """A stop at live time stop [s] lasting pause [s] was caught: PAUSED and
    held within 0.1 s of the truth from held_from [s] into it to its end,
    and within 50 ms again from 1.5 s after the restart on."""
    t = np.arange(len(err)) * T
    held = (t > stop + held_from) & (t < stop + pause)
    return bool(np.all(track.state[held] == PAUSED) and np.all(np.abs(err[held]) <= 0.1)
                and np.all(np.abs(err[t >= stop + pause + 1.5]) <= 0.05))


def lock_entries(track):
    """Ticks at which the follower entered LOCKED (from any other state)."""
    before = np.concatenate([[-1], track.state[:-1]])
    return np.flatnonzero((track.state == LOCKED) & (before != LOCKED))


@functools.cache
def taught(style, seed):
    """A synthesized piece and its stored loudness, made once per session."""
    piece = synthesize(style, seed=seed)
    return piece, loudness(piece.samples, piece.sample_rate)


def room_deck(rng, starts, seconds):
    """A random deck in a reverberant room (RT60 0.3-0.6 s, 20 dB SNR), its
    start drawn from starts = (first, last) [s], seconds long."""
    return Deck(speed=float(rng.uniform(0.95, 1.05)), wow=0.003, wow_hz=0.6, snr_db=20.0,
                reverb_s=float(rng.uniform(0.3, 0.6)), sample_rate=16000,
                start=float(rng.uniform(*starts)), seconds=seconds, seed=int(rng.integers(1000)))


@functools.cache
def taught_onsets(style, seed):
    """The onset strength of taught(style, seed)'s piece, made once per session."""
    piece, _ = taught(style, seed)
    return onsets(piece.samples, piece.sample_rate)


def taught_with_onsets(*styles):
    """For each (style, seed): the style, its synthesized piece, stored
    loudness and stored onsets (each made once per session)."""
    for style, seed in styles:
        yield (style, *taught(style, seed), taught_onsets(style, seed))


def onset_track(piece, stored, stored_onsets, deck, start=None):
    """Runs the follower with onsets over the deck's recording (live loudness
    and onset strength); start: a known start [stored ticks]. (track, played)"""
    played = play(piece.samples, piece.sample_rate, deck)
    live = sync_ticks(loudness(played.samples, played.sample_rate))[:len(played.truth)]
    live_onsets = sync_ticks(onsets(played.samples, played.sample_rate))[:len(played.truth)]
    f = Follower(stored, onset=stored_onsets)
    if start is not None:
        f.reset(start)
    return f.run(live, live_onsets), played


def lock_errors(style, seed, deck):
    """Errors [s] at the ticks the follower entered LOCKED, over the deck's
    recording of the synthesized piece (style, seed)."""
    track, _, err, _ = live_track(*taught(style, seed), deck)
    return err[lock_entries(track)]

def test_c_follower_under_asan_ubsan_without_step_allocations(tmp_path, sanitized_build):
    if shutil.which("gcc") is None:
        pytest.skip("needs gcc")
    exe = tmp_path / "test_follow"
    sources = [*sorted(str(p) for p in (ROOT / "ext").glob("mar_follow*.c")),
               str(ROOT / "ext" / "tests" / "test_follow.c")]
    build = sanitized_build.link(exe, [(sources, FOLLOW_CFLAGS)],
                                 ["-lm", "-Wl,--wrap=malloc,--wrap=calloc,--wrap=realloc,--wrap=free"])
    assert build.returncode == 0 and not build.stderr, build.stderr
    run = subprocess.run([str(exe)], capture_output=True, text=True, timeout=300,
                         env={"ASAN_OPTIONS": "detect_leaks=1", "UBSAN_OPTIONS": "print_stacktrace=1"})
    assert run.returncode == 0, run.stdout + run.stderr
    assert "C follower tests passed" in run.stdout


def test_locks_and_follows_a_three_percent_fast_tape(piece, stored):
    deck = Deck(speed=1.03, wow=0.002, flutter=0.0005, snr_db=30.0, sample_rate=22050, seed=1)
    track, played, err, f = live_track(piece, stored, deck)
    assert first_lock(track, err) <= 4.0
    after = np.arange(len(err)) * T >= 5.0
    assert np.mean(np.abs(err[after]) <= 0.020) >= 0.95
    assert np.max(np.abs(err[after])) <= 0.1
    # the rate is the tape's speed
    assert abs(np.median(track.rate[after]) - 1.03) < 0.003
    assert np.all(track.state[after] != STATES.index("searching"))


def test_paper_mode_doubles_or_skips_whole_samples(piece, stored):
    deck = Deck(speed=1.03, snr_db=30.0, seed=2)
    track, played, err, f = live_track(piece, stored, deck, mode="paper")
    following = track.state != STATES.index("searching")
    assert np.any(following)
    assert set(np.unique(track.rate[following])) <= {0.0, 1.0, 2.0}
    assert np.all(track.position[following] == np.round(track.position[following]))
    after = np.arange(len(err)) * T >= 5.0
    assert np.mean(np.abs(err[after]) <= 0.050) >= 0.9       # the baseline still follows


def test_holds_through_a_pause_and_resumes(piece, stored):
    deck = Deck(speed=0.97, snr_db=30.0, pauses=((20.0, 4.0),), start=10.0, seed=3)
    track, played, err, f = live_track(piece, stored, deck)
    t = np.arange(len(err)) * T
    paused = (t > 20.5) & (t < 24.0)
    assert np.all(track.state[paused] == PAUSED)
    assert np.all(track.rate[paused] == 0.0)
    assert np.max(np.abs(err[paused])) <= 0.05               # held where the tape stopped
    after = (t >= 24.0 + 0.5) & (t < 40.0)
    assert np.all(np.abs(err[after]) <= 0.05)                # going on from there
    assert np.all(track.state[after] != PAUSED)
    assert f.counters()["pauses"] == 1 and f.counters()["resumes"] == 1


def test_a_deck_that_backs_up_on_restart_is_found_near_the_stop(piece, stored):
    """Some decks back the tape up a little when restarted. Six random cases:
    a pause of 2-4 s, and the tape goes on 0.3-0.8 s before where it stopped,
    further than the tracker's gate reaches. The near search around the stop
    finds the place within 1.5 s of the restart; nothing locks elsewhere."""
    rng = np.random.default_rng(2026)
    for case in range(6):
        start, stop = float(rng.uniform(0.0, 60.0)), float(rng.uniform(15.0, 25.0))
        pause, back = float(rng.uniform(2.0, 4.0)), float(rng.uniform(0.3, 0.8))
        speed = float(rng.uniform(0.96, 1.04))
        restart = stop + pause
        deck = Deck(speed=speed, snr_db=30.0, start=start, pauses=((stop, pause),),
                    jump=(restart, start + speed * stop - back), seconds=restart + 12.0, seed=case)
        track, played, err, f = live_track(piece, stored, deck)
        t = np.arange(len(err)) * T
        after = t >= restart + 1.5
        assert np.max(np.abs(err[after])) <= 0.05, (case, start, stop, back)
        entered = lock_entries(track)
        assert np.all(np.abs(err[entered]) <= 0.2), (case, start, stop, back)


def test_finds_an_unknown_start_without_false_locks(piece, stored):
    """Six random starts: each locks, most within 3 s; a start early in a
    repeated chorus takes longer (its twins match as well until the window
    reaches music that differs), but no lock is ever off by more than 0.2 s."""
    rng = np.random.default_rng(100)
    times = []
    for case in range(6):
        start = float(rng.uniform(0.0, piece.duration - 40.0))
        deck = Deck(speed=float(rng.uniform(0.95, 1.05)), wow=0.003, snr_db=25.0, start=start,
                    sample_rate=float(rng.choice([11025, 16000, 22050])), seconds=30.0, seed=case)
        track, played, err, f = live_track(piece, stored, deck)
        times.append(first_lock(track, err))
        entered = lock_entries(track)
        assert np.all(np.abs(err[entered]) <= 0.2), (case, start)
        assert np.all(np.abs(err[track.state == LOCKED]) <= 0.2), (case, start)
    assert max(times) <= 12.0, times
    assert sum(t <= 3.0 for t in times) >= 4, times


@pytest.mark.parametrize("deck", [
    Deck(speed=0.95, drift=0.005, wow=0.004, wow_hz=0.5, flutter=0.001, flutter_hz=8.0, snr_db=20.0,
         reverb_s=0.5, start=13.979717907493425, sample_rate=16000, seed=301),
    Deck(speed=0.94, wow=0.005, wow_hz=1.0, flutter=0.002, flutter_hz=10.0, snr_db=30.0, reverb_s=0.3,
         start=46.62691562420911, jump=(33.7163659757458, 21.076881282805015), sample_rate=22050,
         seed=306)], ids=["room", "jump"])
def test_the_twin_of_a_repeated_section_is_not_locked_on(deck):
    """The ambient piece repeats its first section 68.6 s later; in a
    reverberant room the right place and its twin correlate alike. Two
    decks (from bench sync seeds 100 and 103) on which the follower used to
    lock on the twin: the twin had been scored on a shorter window than the
    right place, and a shorter window scores higher. Every lock must now be
    at the right place."""
    errors = lock_errors("ambient", 3, deck)
    assert len(errors) >= 1
    assert np.all(np.abs(errors) <= 0.2), errors


@pytest.mark.parametrize("style,seed,deck", [
    ("pop", 1, Deck(speed=0.94, wow=0.005, wow_hz=1.0, flutter=0.002, flutter_hz=10.0, snr_db=30.0,
                    reverb_s=0.3, start=19.19127906823751, jump=(43.11796526543097, 42.29273604099656),
                    sample_rate=22050, seed=205)),
    ("techno", 4, Deck(speed=1.06, wow=0.001, wow_hz=0.9, snr_db=20.0, start=28.94162551195993,
                       gain_db=((0.0, 0.0), (38.19079246832746, 0.0), (40.19079246832746, 20.0)),
                       pauses=((70.41266798913429, 5.770421344105322),), sample_rate=11025, seconds=60.0,
                       seed=20261426))], ids=["pop", "techno"])
def test_a_first_lock_beats_places_the_pool_had_no_room_for(style, seed, deck):
    """Repetitive music: after 2-4 s more than 16 places score high, and the
    right one may not be in the search's pool at all. Two decks (from bench
    sync seeds 202 and 20261124) on which the follower used to lock 34 s and
    135 s off: a lock must also beat the last sweep's best places."""
    errors = lock_errors(style, seed, deck)
    assert len(errors) >= 1
    assert np.all(np.abs(errors) <= 0.2), errors


def test_one_fitting_measurement_after_a_long_bad_stretch_does_not_relock():
    """The tape jumps 12 s ahead in the ambient piece (bench sync seed
    20261123). The tracker, still at the old place, used to find one
    measurement that passed a second later and went back to LOCKED 13.5 s
    off. After a stretch of bad measurements long enough to start the
    search beside, the place must fit REGAIN_TICKS measurements in a row
    before it is LOCKED again."""
    deck = Deck(speed=0.94, wow=0.005, wow_hz=1.0, flutter=0.002, flutter_hz=10.0, snr_db=30.0,
                reverb_s=0.3, start=1.7486197521972227, jump=(53.892387571690605, 65.8302234171546),
                sample_rate=22050, seed=20261326)
    errors = lock_errors("ambient", 3, deck)
    assert len(errors) >= 2                                   # before and after the jump
    assert np.all(np.abs(errors) <= 0.2), errors


def test_a_jump_into_alike_music_is_not_taken_for_a_pause(piece, stored):
    """The tape jumps from the end of a verse to the end of a chorus (the
    same drums, then the quiet break): the follower must not read the
    break as a pause and loop through resumes at the old place; it searches
    and re-locks at the new place, and never locks at a wrong one."""
    deck = Deck(speed=0.94, wow=0.005, wow_hz=1.0, reverb_s=0.3, snr_db=30.0, sample_rate=22050,
                start=9.93, jump=(47.7, 71.26), seconds=70.0, seed=3)
    track, played, err, f = live_track(piece, stored, deck)
    t = np.arange(len(err)) * T
    entered = lock_entries(track)
    assert np.all(np.abs(err[entered]) <= 0.2)
    assert np.all(np.abs(err[(track.state == LOCKED) & (t >= 49.0)]) <= 0.2)
    assert f.counters()["pauses"] == 0                        # the tape never stopped
    assert first_lock(track, err, after=47.7) - 47.7 <= 8.0
    assert np.all(np.abs(err[t >= 58.0]) <= 0.05)


def test_resumes_in_time_where_the_music_restarts_quietly(piece, stored):
    """Two pauses, the second ending just before a gap in the music (the
    last chorus note, then silence, then the outro): the resume is placed
    where the music rose over the hiss, within 50 ms after at most 0.5 s."""
    deck = Deck(speed=1.06, wow=0.001, wow_hz=0.9, snr_db=20.0, sample_rate=11025, start=37.1,
                pauses=((60.67, 5.82), (69.5, 3.04)), seed=202)
    track, played, err, f = live_track(piece, stored, deck)
    t = np.arange(len(err)) * T
    restart = 69.5 + 3.04                                     # the second pause's end
    ok = np.flatnonzero((np.abs(err) <= 0.05) & (track.state != PAUSED) & (t >= restart))
    assert len(ok) and t[ok[0]] - restart <= 0.5
    entered = lock_entries(track)
    assert np.all(np.abs(err[entered]) <= 0.2)


def test_a_pause_in_a_quiet_passage_is_caught(piece, stored):
    """The tape stops where the music is so quiet that most of its frames
    lie under the hiss (taught 75.9 s on): the few frames where music should
    stand over the hiss, and hiss-flat frames between them for a second,
    mean a pause. Six decks; each holds within 0.1 s of where the tape
    stopped; most resume within 0.5 s (a resume can still fail its
    probation, docs/music.md)."""
    resumed = 0
    for seed in range(6):
        deck = Deck(speed=1.06, wow=0.001, wow_hz=0.9, snr_db=20.0, sample_rate=11025, start=60.0,
                    pauses=((15.0, 6.0),), seconds=30.0, seed=seed)
        track, played, err, f = live_track(piece, stored, deck)
        t = np.arange(len(err)) * T
        held = (t > 16.5) & (t < 21.0)                        # the pause, once caught
        assert np.all(track.state[held] == PAUSED), seed
        assert np.max(np.abs(err[held])) <= 0.1, seed
        ok = np.flatnonzero((np.abs(err) <= 0.05) & (track.state != PAUSED) & (t >= 21.0))
        resumed += bool(len(ok)) and t[ok[0]] - 21.0 <= 0.5
    assert resumed >= 5


def test_a_volume_turned_down_in_a_passage_under_the_hiss_is_not_a_stop(piece):
    """The music falls 30 dB, under the tape's hiss, for 8 s (taught 40-48
    s of a copy of the piece), and the volume is turned 20-30 dB down over
    2-3 s as it falls. The follower, started at its place, heard the hiss
    in a short stop before; a live level under that hiss can only be the
    knob, so the passage is no stop: never PAUSED in it, and within 0.1 s
    of the place when the music returns. Eight random decks; before the
    knob was read from the hiss, every one was taken for a stop 1.4-3.3 s
    into the passage and stood 5-8 s behind by its end."""
    quiet = (40.0, 48.0)                                       # the passage, taught [s]
    x = piece.samples.copy()
    x[int(quiet[0] * piece.sample_rate):int(quiet[1] * piece.sample_rate)] *= 10 ** (-30 / 20)
    quiet_piece = dataclasses.replace(piece, samples=x)
    taught_quiet = loudness(x, piece.sample_rate)
    rng = np.random.default_rng(20261207)
    for case in range(8):
        speed, start, stop = rng.uniform(0.96, 1.04), 25.0, (3.0, 1.5)   # [1], taught [s], live (at, for) [s]
        fall = stop[0] + stop[1] + (quiet[0] - start - stop[0] * speed) / speed    # live [s]
        rise = fall + (quiet[1] - quiet[0]) / speed                                # live [s]
        turn = fall + rng.uniform(-0.5, 0.5)                                       # live [s]
        deck = Deck(speed=speed, snr_db=20.0, sample_rate=11025, start=start, pauses=(stop,),
                    gain_db=((0.0, 0.0), (turn, 0.0), (turn + rng.uniform(2.0, 3.0), -rng.uniform(20.0, 30.0))),
                    seconds=rise + 3.0, seed=case)
        track, _, err, _ = live_track(quiet_piece, taught_quiet, deck, start=start / T)
        t = np.arange(len(err)) * T
        inside = (t > fall) & (t < rise)
        assert not np.any(track.state[inside] == PAUSED), case
        assert abs(err[int(rise / T)]) <= 0.1, case


def test_a_stop_soon_after_a_volume_turn_is_caught(piece, stored):
    """The volume is turned 20 dB up or down over 2 s, and 0.5-6 s later
    the tape stops for 2-4 s. The turn may leave the place HOLDING (the
    correlation drops while the feature's clamp catches up with the knob);
    a stop there must still be caught: held within 0.1 s of the place, and
    within 50 ms again from 1.5 s after the restart. Sixteen random decks;
    the few where the follower was not on the place before the stop (a
    slow or wrong first lock) do not count."""
    rng = np.random.default_rng(11)
    valid = caught = 0
    for seed in range(16):
        start, turn = rng.uniform(0.0, 60.0), rng.uniform(8.0, 12.0)       # [s]
        stop, pause = turn + rng.uniform(0.5, 6.0), rng.uniform(2.0, 4.0)   # [s]
        gain = ((0.0, 0.0), (turn, 0.0), (turn + 2.0, float(rng.choice([-20.0, 20.0]))))
        deck = Deck(speed=rng.uniform(0.96, 1.04), snr_db=20.0, start=start, gain_db=gain,
                    pauses=((stop, pause),), seconds=stop + pause + 6.0, seed=seed)
        track, _, err, _ = live_track(piece, stored, deck)
        if abs(err[int((stop - 0.1) / T)]) > 0.05:
            continue
        valid += 1
        caught += stop_caught(track, err, stop, pause, held_from=0.5)
    assert valid >= 12
    assert caught >= valid - 2                                # before: 7 of 15


def test_a_stop_during_a_volume_turn_is_caught():
    """The volume is turned 20-30 dB up over 2-3 s and the tape stops
    during the turn or within a second of its end, for 3-6 s (pop, techno
    and waltz decks at 11 kHz, 20 dB SNR, known start). The gain estimate
    lags the knob, so the hiss of the stop stands about where the music is
    expected; the stop shows as a fall onto a level that stands still
    while the music expected moves (stands_still in ext/mar_follow.c).
    Held within 0.1 s from 1 s into the stop, within 50 ms again from
    1.5 s after the restart. Eighteen random decks; the few where the
    follower was not on the place before the turn do not count."""
    rng = np.random.default_rng(21)
    valid = caught = 0
    for seed in range(18):
        style, piece_seed = (("pop", 1), ("techno", 4), ("waltz", 2))[seed % 3]
        start, turn = rng.uniform(5.0, 50.0), rng.uniform(8.0, 12.0)              # [s]
        up, span = rng.uniform(20.0, 30.0), rng.uniform(2.0, 3.0)                 # [dB], [s]
        stop, pause = turn + rng.uniform(0.0, span + 1.0), rng.uniform(3.0, 6.0)  # [s]
        deck = Deck(speed=rng.uniform(0.96, 1.04), snr_db=20.0, start=start, sample_rate=11025,
                    gain_db=((0.0, 0.0), (turn, 0.0), (turn + span, up)),
                    pauses=((stop, pause),), seconds=stop + pause + 6.0, seed=seed)
        track, _, err, _ = live_track(*taught(style, piece_seed), deck, start=start / T)
        if abs(err[int((turn - 0.1) / T)]) > 0.05:
            continue
        valid += 1
        caught += stop_caught(track, err, stop, pause, held_from=1.0)
    assert valid >= 15
    assert caught >= 12                                       # before stands_still: 6 of 18

@pytest.mark.xfail(strict=True, reason="known limit (docs/music.md): since the follower is "
                   "stepped per tick as in the engine (no step at tick 0), deck 6 locks on the "
                   "twin of the repeated section 68.6 s away; the place model of issue 21 is to fix it")
def test_a_long_first_search_listens_longer():
    """Slow pads in a reverberant room look alike over 5 s at many places:
    once the first search has run 5 s, its verification window grows a
    tick per tick up to 10 s. Ten random ambient decks from unknown starts:
    every one locks within 200 ms of the truth within 40 s, the median
    within 15 s (with the 5 s window: one never locked, median 20 s)."""
    piece, stored = taught("ambient", 3)
    rng = np.random.default_rng(31)
    lock_s = []
    for case in range(10):
        track, _, err, _ = live_track(piece, stored, room_deck(rng, (0.0, 100.0), 60.0))
        lock_s.append(first_lock(track, err, within=0.2))
    assert max(lock_s) <= 40.0 and np.median(lock_s) <= 15.0, lock_s


def test_a_pause_holds_where_the_tape_stopped():
    """The held position is fitted to the frames around the stop (music as
    stored before it, the silence's level after): within 100 ms of where the
    tape stopped in 24 random pop and techno decks (known start, one pause
    of 2-5 s; 79 ms at worst, median 6 ms). The walk back to the last loud
    frame held up to 311 ms off in techno, where hiss between the hits
    reads as music."""
    rng = np.random.default_rng(21)
    errors = []
    for style, seed in (("pop", 1), ("techno", 4)):
        piece, stored = taught(style, seed)
        for case in range(12):
            start, at = float(rng.uniform(5.0, 60.0)), float(rng.uniform(8.0, 25.0))          # [s]
            deck = Deck(speed=float(rng.uniform(0.95, 1.05)), wow=0.002, snr_db=float(rng.uniform(20, 30)),
                        sample_rate=16000, start=start, pauses=((at, float(rng.uniform(2.0, 5.0))),),
                        seconds=at + 8.0, seed=int(rng.integers(1000)))
            played = play(piece.samples, piece.sample_rate, deck)
            live = sync_ticks(loudness(played.samples, played.sample_rate))[:len(played.truth)]
            f = Follower(stored)
            f.reset(start / T)
            track = f.run(live)
            held = np.flatnonzero((track.state == PAUSED) & played.paused[:len(track.state)])
            assert len(held), (style, case)
            errors.append(abs(track.position[held[0]] * T - played.truth[held[0]]))
    assert max(errors) <= 0.100 and np.median(errors) <= 0.010, np.round(np.array(errors) * 1e3, 1)


def test_a_fade_read_as_a_stop_is_found_again_where_the_music_went_on():
    """A volume turn down by 20-30 dB in 1.5-3 s during a quiet passage
    reads as a stop (docs/music.md, known limits); the tape never stops
    here. When the music rises again it plays on from where it would have
    been, seconds past the held place, out of the resumed place's reach:
    the near search also looks there. Forty random ambient decks (known
    start): 5 such false pauses, 4 of them back within 50 ms 0.8 s after
    the pause ends. Searching the whole piece instead, none was back
    within 1 s (2.3-15 s)."""
    piece, stored = taught("ambient", 3)
    stored_onsets = taught_onsets("ambient", 3)
    rng = np.random.default_rng(2)
    back_after = []                                           # [s] per false pause
    for case in range(40):
        turn = float(rng.uniform(8.0, 25.0))                  # [s]
        deck = Deck(speed=float(rng.uniform(0.95, 1.05)), wow=0.001, snr_db=20.0, sample_rate=11025,
                    start=float(rng.uniform(0.0, piece.duration - 60.0)), seconds=45.0,
                    gain_db=((0.0, 0.0), (turn, 0.0), (turn + float(rng.uniform(1.5, 3.0)),
                                                       -float(rng.uniform(20.0, 30.0)))),
                    seed=int(rng.integers(1000)))
        track, played = onset_track(piece, stored, stored_onsets, deck, start=deck.start / T)
        err = np.abs(track.position * T - played.truth)
        for end in np.flatnonzero((track.state[:-1] == PAUSED) & (track.state[1:] != PAUSED)) + 1:
            good = np.flatnonzero(err[end:] <= 0.05)
            back_after.append(good[0] * T if len(good) else math.inf)
    assert len(back_after) >= 4 and np.sum(np.array(back_after) <= 1.0) >= 3, back_after


def test_a_tape_wound_while_stopped_is_not_locked_a_bar_off():
    """The operator stops the tape, winds it 1.3-2.8 s either way and
    starts it again: the resumed place is wrong by more than the near
    search's reach (1 s), and music that repeats by the bar shows a peak
    within reach a bar off the truth. The near search takes a peak only if
    it leads every place within 3 s either way, so the whole-piece search
    finds the place instead. Ten random decks each of waltz, pop and techno
    (known start, one pause): no lock more than 0.5 s off the truth. With
    rivals counted only within reach, 12 of them locked a bar off. (A wind
    past 3 s may still: docs/music.md, known limits.)"""
    rng = np.random.default_rng(31)
    wrong = []
    for style, piece, stored, stored_onsets in taught_with_onsets(("waltz", 2), ("pop", 1), ("techno", 4)):
        for case in range(10):
            start, at, pause = (float(rng.uniform(*r)) for r in ((5.0, 40.0), (12.0, 20.0), (2.0, 4.0)))
            speed = float(rng.uniform(0.95, 1.05))
            wound = float(rng.choice([-1.0, 1.0]) * rng.uniform(1.3, 2.8))         # [s] of music
            deck = Deck(speed=speed, snr_db=30.0, sample_rate=16000, start=start, pauses=((at, pause),),
                        jump=(at + 0.5 * pause, start + at * speed + wound), seconds=at + pause + 10.0,
                        seed=int(rng.integers(1000)))
            track, played = onset_track(piece, stored, stored_onsets, deck, start=start / T)
            err = track.position * T - played.truth
            wrong += [(style, case, round(float(err[k]), 2)) for k in lock_entries(track) if abs(err[k]) > 0.5]
    assert not wrong, wrong


def test_after_a_long_hold_weak_fits_do_not_claim_a_lock():
    """More than a second without a fitting measurement leaves the place
    the flywheel's guess: LOCKED comes back by a lock, or once the
    confidence has recovered to 0.5, not on the first weak fit. The case
    behind it: in the waltz's pianissimo passage (under the hiss) a stop
    goes unnoticed; if it lasts a whole number of bars the flywheel lands
    bars off, and faint music fits there too. Twenty random decks (known
    start, the volume turned up 20 dB before the stop): every return to
    LOCKED without a lock after such a hold has confidence 0.5 or more.
    Before, 10 returns came at 0.10-0.39, two of them 2.1 and 3.2 s off."""
    piece, stored = taught("waltz", 2)
    stored_onsets = taught_onsets("waltz", 2)
    bar = 3 * 60.0 / 168.0                                    # [s] of music
    rng = np.random.default_rng(5)
    returns, weak = 0, []
    for case in range(20):
        speed, start = float(rng.uniform(0.95, 1.05)), float(rng.uniform(40.0, 46.0))
        at = (float(rng.uniform(52.0, 57.0)) - start) / speed                   # [s] live: in the pp
        stop = (int(rng.integers(2, 4)) * bar + float(rng.uniform(-0.06, 0.06))) / speed    # [s]
        deck = Deck(speed=speed, wow=0.001, snr_db=20.0, sample_rate=11025, start=start,
                    pauses=((at, stop),), gain_db=((0.0, 0.0), (at - 6.0, 0.0), (at - 4.0, 20.0)),
                    seconds=at + 12.0, seed=int(rng.integers(1000)))
        track, _ = onset_track(piece, stored, stored_onsets, deck, start=start / T)
        measured = (track.flags & FLAGS["measured"]) != 0
        gap = longest = 0                 # ticks without a measurement: now, longest since LOCKED
        for k in range(1, len(track.state)):
            if (track.state[k] == LOCKED and track.state[k - 1] == HOLDING
                    and not track.flags[k] & FLAGS["jump"] and longest > 50):
                returns += 1
                if track.confidence[k] < 0.5:
                    weak.append((case, round(float(track.confidence[k]), 2)))
            gap = 0 if measured[k] else gap + 1
            longest = 0 if track.state[k] == LOCKED else max(longest, gap)
    assert returns >= 5 and not weak, (returns, weak)


def test_a_stop_while_searching_starts_the_search_again_at_the_restart():
    """While searching there is no place to expect music at, so a stop
    shows only as steady hiss; after a second of it, the search makes no
    lock, and it starts again on the frames from the restart on (those
    before a stop may be another stretch of tape, and silence in the window
    matches quiet stored passages). Forty random decks, ten per style
    (unknown start, a stop of 3-8 s beginning 1.5-3 s in, before the first
    lock): median time from the restart to a lock within 50 ms 2.6 s; 3.6 s
    with the search going on through the stop."""
    rng = np.random.default_rng(2)
    after = []                                                # [s] per deck
    for _, piece, stored, stored_onsets in taught_with_onsets(*FOUR_STYLES):
        for case in range(10):
            at, stop = float(rng.uniform(1.5, 3.0)), float(rng.uniform(3.0, 8.0))       # [s]
            deck = Deck(speed=float(rng.uniform(0.95, 1.05)), wow=0.002, snr_db=float(rng.uniform(20, 30)),
                        sample_rate=16000, start=float(rng.uniform(5.0, piece.duration - 40.0)),
                        pauses=((at, stop),), seconds=at + stop + 20.0, seed=int(rng.integers(1000)))
            track, played = onset_track(piece, stored, stored_onsets, deck)
            err = track.position * T - played.truth
            after.append(first_lock(track, err, after=at + stop) - at - stop)
    assert np.median(after) <= 3.0, np.round(after, 2)


def test_a_small_jump_is_found_by_the_search_beside():
    """A jump of 0.1-0.45 s (a splice, a skip) lies beyond the tracking lags
    but within 0.5 s, where the search's candidates count as one place.
    The tracker's own pool entry stands only for its lags, so the search
    verifies the place a few ticks away and locks there. Forty random
    decks, ten per style (known start, one jump either way): median time
    from the jump to LOCKED within 50 ms 3.7 s; 6.4 s while the tracker's
    entry took in every offer within 0.5 s."""
    rng = np.random.default_rng(1)
    after = []                                                # [s] per deck
    for _, piece, stored, stored_onsets in taught_with_onsets(*FOUR_STYLES):
        for case in range(10):
            speed, start = float(rng.uniform(0.95, 1.05)), float(rng.uniform(5.0, piece.duration - 50.0))
            at = float(rng.uniform(10.0, 20.0))                                    # [s] live
            by = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.1, 0.45))            # [s] of music
            deck = Deck(speed=speed, wow=0.002, snr_db=30.0, sample_rate=16000, start=start,
                        jump=(at, start + at * speed + by), seconds=at + 20.0, seed=int(rng.integers(1000)))
            track, played = onset_track(piece, stored, stored_onsets, deck, start=start / T)
            after.append(first_lock(track, track.position * T - played.truth, after=at) - at)
    assert np.median(after) <= 4.5, np.round(after, 2)


def test_onsets_keep_the_place_in_a_reverberant_room():
    """A room colours each held chord by its own gain, which moves the
    loudness correlation's peak; the onset strength does not carry it.
    Eight random decks of the ambient piece (pads, few onsets) in rooms
    with RT60 0.3-0.6 s, known start: the share of ticks within 20 ms.
    Loudness alone keeps 2 of them within 20 ms for 80 % of the ticks. Two
    decks (4.4 % fast from 71 s) lose the place before the tracker has the
    rate, and the whole-piece search does not find it again in the room
    (docs/music.md, known limits)."""
    piece, stored = taught("ambient", 3)
    stored_onsets = taught_onsets("ambient", 3)
    rng = np.random.default_rng(12)
    shares = []
    for case in range(8):
        deck = room_deck(rng, (10.0, 80.0), 40.0)
        track, played = onset_track(piece, stored, stored_onsets, deck, start=deck.start / T)
        err = np.abs(track.position * T - played.truth)[int(3.0 / T):]
        shares.append(np.mean(err <= 0.020))
    assert np.sum(np.array(shares) >= 0.8) >= 6, np.round(shares, 3)


def test_a_lock_takes_the_onset_features_second_opinion_on_the_rate():
    """A lock's rate comes from the lags of two half windows; in a room the
    loudness lags of held chords wander, so the onset feature measures the
    same correction again and the lock takes the mean of the two. Twelve
    random ambient room decks (unknown start): at the first lock within
    0.2 s of the truth the rate is off from the deck's speed by 0.12 % in
    the median (0.32 % on the loudness alone)."""
    piece, stored = taught("ambient", 3)
    stored_onsets = taught_onsets("ambient", 3)
    rng = np.random.default_rng(7)
    rate_errors = []
    for case in range(12):
        deck = room_deck(rng, (0.0, 100.0), 40.0)
        track, played = onset_track(piece, stored, stored_onsets, deck)
        entries = lock_entries(track)
        right = entries[np.abs(track.position[entries] * T - played.truth[entries]) <= 0.2]
        if len(right):
            rate_errors.append(abs(track.rate[right[0]] - deck.speed))
    assert len(rate_errors) >= 10 and np.median(rate_errors) <= 0.002, np.round(rate_errors, 4)


def test_known_start_follows_at_once(piece, stored):
    deck = Deck(speed=1.0, snr_db=30.0, start=30.0, seconds=15.0, seed=4)
    track, played, err, f = live_track(piece, stored, deck, start=30.0 / T)
    assert track.state[0] == HOLDING
    assert np.all(np.abs(err[:100]) <= 0.05)                  # no search, no detour
    assert np.mean(track.state[50:] == LOCKED) > 0.9


@pytest.mark.parametrize("kind", ["silence", "hiss", "missing"])
def test_does_not_wander_on_silence_or_noise(stored, kind):
    rng = np.random.default_rng(7)
    n = 3000                                                  # 60 s
    if kind == "silence":
        live = np.zeros(n)
    elif kind == "hiss":
        live = 1e-3 * np.exp(rng.normal(0.0, 0.05, n))        # steady noise, about -60 dBFS
    else:
        live = np.full(n, np.nan)
    # from nothing: never locks, stays at rate 0
    f = Follower(stored)
    track = f.run(live)
    assert np.all(track.state == STATES.index("searching"))
    assert np.all(track.rate == 0.0) and np.all(track.position == 0.0)
    assert f.counters()["locks"] == 0
    # following the music from tick 500, then the input goes quiet at 1500
    f = Follower(stored)
    f.reset(500.0)
    f.run(sync_ticks(stored[500:1500])[:1000])
    track = f.run(live)
    assert f.counters()["locks"] == 0                         # no lock anywhere else
    steps = np.diff(np.concatenate([[1500.0], track.position]))
    assert np.all((steps >= -15.0) & (steps <= 1.1 + 1e-9))  # the flywheel, or back to the pause's start
    assert not np.any(track.state[200:] == LOCKED)
    if kind in ("silence", "hiss"):                           # the recorder stopped: held there
        assert np.all(track.state[20:] == PAUSED)
        assert np.all(track.position[20:] == track.position[-1])
        assert 1490.0 <= track.position[-1] <= 1502.0        # (the music itself is silent from 1495)
    else:                                                     # no frames: the flywheel at the rate
        assert abs(track.position[-1] - (1500.0 + n)) < 0.05 * n


def test_bad_input_is_refused_without_disturbing_the_state(stored):
    rng = np.random.default_rng(11)
    for case in range(20):
        start = int(rng.integers(0, len(stored) - 2000))
        live = stored[start:start + 1500] * 10 ** (rng.uniform(-20, 20) / 20)
        live = np.where(rng.random(len(live)) < 0.05, np.nan, live)
        bad_at = rng.random(len(live)) < 0.05
        bad = rng.choice([-1.0, -1e-9, np.inf, -np.inf, -1e300], len(live))
        polluted = np.where(bad_at, bad, live)
        missing = np.where(bad_at, np.nan, live)
        a, b = Follower(stored), Follower(stored)
        ta, tb = a.run(polluted), b.run(missing)
        for key in ("position", "rate", "confidence", "state"):
            assert np.array_equal(getattr(ta, key), getattr(tb, key)), key
        flagged = (ta.flags & 2) != 0                         # MAR_FOLLOW_F_BAD_INPUT
        assert np.array_equal(flagged, bad_at)
        assert a.counters()["bad_input"] == int(bad_at.sum())
        assert b.counters()["bad_input"] == 0


def test_step_and_run_agree(stored):
    live = sync_ticks(stored[2000:3000] * 0.3)
    a, b = Follower(stored), Follower(stored)
    ta = a.run(live)
    steps = [b.step(x) for x in live]
    assert np.array_equal(ta.position, [s.position for s in steps])
    assert [STATES[s] for s in ta.state] == [s.state for s in steps]


def test_python_api_refuses_bad_arguments(stored):
    with pytest.raises(FollowError, match="stored loudness\\[1\\]"):
        Follower([0.1, -0.5, 0.2])
    with pytest.raises(FollowError, match="at least 2"):
        Follower([0.1])
    with pytest.raises(FollowError, match="unknown option 'speed'"):
        Follower(stored, speed=2)
    with pytest.raises(FollowError, match="1-d"):
        Follower(stored).run(np.zeros((2, 2)))
    with pytest.raises(FollowError, match="stored onsets: shape"):
        Follower(stored, onset=np.zeros(3))
    with pytest.raises(FollowError, match="stored onset\\[2\\] = nan"):
        Follower(stored, onset=np.where(np.arange(len(stored)) == 2, np.nan, 0.0))
    with pytest.raises(FollowError, match="live onsets: shape"):
        Follower(stored, onset=np.zeros(len(stored))).run(np.zeros(5), np.zeros(4))


def test_one_table_of_options_from_c_to_the_figure():
    """The C table (ext/mar_follow.h) gives FollowConfig its fields and
    defaults and the TOML its ranges; c_options hands the settings through
    in seconds with the tick period, and C turns them into ticks."""
    defaults = FollowConfig()
    for name, info in OPTIONS.items():
        assert hasattr(defaults, name), name
        if name not in ("latency", "mode"):
            assert getattr(defaults, name) == info["default"], name
        assert info["lo"] <= info["default"] <= info["hi"], name
    opt = c_options(FollowConfig(window=3.0, latency=0.04, lost_after=2.0, rate_min=0.5, rate_max=3.0),
                    period=0.01)
    assert (opt["window"], opt["latency"], opt["lost_after"], opt["tick_period"]) == (3.0, 0.04, 2.0, 0.01)
    stored = np.abs(np.sin(np.arange(500) * 0.1)) + 0.1
    Follower(stored, FollowConfig(rate_min=0.5, rate_max=3.0))       # a fine grid is widened, not refused
    for period in (0.005, 0.010, 0.025, 0.040):
        assert Follower(stored, period=period).options["tick_period"] == period
    with pytest.raises(FollowError, match="min_window and paper_window must be at least 4 ticks"):
        Follower(stored, period=0.2)                                 # the 0.5 s paper window: 2 ticks
    with pytest.raises(FollowError, match="window and verify_window must lie between"):
        Follower(stored, window=0.5)
    with pytest.raises(FollowError, match=r"lock_threshold = 1.5 must be in \[0, 0.99\]"):
        Follower(stored, lock_threshold=1.5)
    with pytest.raises(FollowError, match="search_budget = 2.5 is not a value of its kind"):
        Follower(stored, search_budget=2.5)


def test_the_docs_table_of_options_is_the_c_table():
    doc = (Path(__file__).resolve().parents[1] / "docs" / "music.md").read_text()
    start = doc.index("<!-- options table: generated, do not edit by hand -->\n")
    end = doc.index("<!-- end of options table -->")
    assert doc[start:end].split("\n", 1)[1] == options_markdown()


def test_follow_table_in_the_figure_config():
    d = figure_dict()
    assert config_from_dict(d, "f.toml").follow == FollowConfig()
    d["follow"] = {"mode": "paper", "rate_max": 1.2, "window": 2.5, "search_budget": 100}
    cfg = config_from_dict(d, "f.toml").follow
    assert (cfg.mode, cfg.rate_max, cfg.window, cfg.search_budget) == ("paper", 1.2, 2.5, 100)
    for table, message in [({"mode": "fast"}, "f.toml: follow.mode = 'fast'"),
                           ({"rate_min": 1.5}, "f.toml: follow.rate_min = 1.5 must be in"),
                           ({"speed": 1}, "f.toml: follow.speed = 1 is not a known key"),
                           ({"window": "long"}, "f.toml: follow.window = 'long' is not a number"),
                           ({"search_budget": 0}, "f.toml: follow.search_budget = 0"),
                           ({"lock_threshold": float("nan")}, "follow.lock_threshold = nan is not finite")]:
        d["follow"] = table
        with pytest.raises(ConfigError, match=message.replace("[", "\\[")):
            config_from_dict(d, "f.toml")
    d["follow"] = 3
    with pytest.raises(ConfigError, match="\\[follow\\] must be a table"):
        config_from_dict(d, "f.toml")


@pytest.mark.parametrize("period", [0.010, 0.040])
def test_the_follower_keeps_time_at_other_tick_periods(period):
    """Every time of the follower is in seconds, turned into ticks at
    create: at 10 and 40 ms ticks it follows the bundled sample as at 20 ms
    (a cue at the top on a fast tape, a pause, an unknown start 15 s in),
    with the stored and the live loudness both made at that period."""
    x, fs = read_wav(sample_path("music.wav"))
    x = mono(x)
    stored, stored_onsets = loudness(x, fs, period), onsets(x, fs, period)
    decks = [(Deck(speed=1.03, snr_db=20, seed=2), 0.0, 3.0),
             (Deck(speed=0.98, snr_db=20, seed=6, pauses=((8.0, 2.0),)), 0.0, 3.0),
             (Deck(speed=1.02, snr_db=20, seed=5, start=15.0), None, 15.0)]
    for deck, cue, lock_by in decks:
        played = play(x, fs, deck, period=period)
        live = loudness(played.samples, played.sample_rate, period)
        live_onsets = onsets(played.samples, played.sample_rate, period)
        f = Follower(stored, period=period, onset=stored_onsets)
        f.cue(cue)
        track = f.run(sync_ticks(live), sync_ticks(live_onsets))
        n = min(len(track.position), len(played.truth)) - 5
        error = np.abs(track.position[:n] * period - played.truth[:n])                # [s]
        locked = np.flatnonzero(track.state[:n] == STATES.index("locked"))
        assert len(locked) and locked[0] * period <= lock_by, (deck, locked[:1] * period)
        assert np.mean(error[locked[0]:] < 0.050) >= 0.97, (deck, np.mean(error[locked[0]:] < 0.050))
