"""The cue (mar_follow_cue): the show waits at a known place through the
silence before the music, plays from the music's onset, and never locks on
the cue's word alone. Random decks from the bench's synthesizer and tape
deck, fixed seeds."""
import functools
from dataclasses import replace

import numpy as np
import pytest

from conftest import make_figure, run_cli
from marionette.engine import Engine
from marionette.music.feature import loudness, onsets, write_wav
from marionette.music.follower import OPTIONS, STATES, Follower, sync_ticks
from marionette.show import Show
from marionette.sim.music import STYLES, synthesize
from marionette.sim.tape import Deck, play

T = 0.020
LOCKED, WAITING, SEARCHING = STATES.index("locked"), STATES.index("waiting"), STATES.index("searching")


def live_frames_of(samples, rate):
    """(loudness, onset strength [dB]) frames of a recording."""
    return loudness(samples, rate), onsets(samples, rate)


@functools.cache
def taught(style, seed):
    """A synthesized piece and its (loudness, onset) frames, made once per session."""
    piece = synthesize(style, seed=seed)
    return piece, live_frames_of(piece.samples, piece.sample_rate)


def track_of(piece, stored, deck, cue):
    played = play(piece.samples, piece.sample_rate, deck)
    loud, onset = live_frames_of(played.samples, played.sample_rate)
    f = Follower(stored[0], onset=stored[1])
    f.cue(cue)
    track = f.run(sync_ticks(loud)[:len(played.truth)], sync_ticks(onset)[:len(played.truth)])
    return track, played, track.position * T - played.truth


def cue_at_the_top(styles, seed, share=0.99, lock_by=2.5):
    """Decks at 0.94-1.06 from the top, 20 dB hiss: within 50 ms on at least
    `share` of the ticks from 1 s on, LOCKED by lock_by [s], never LOCKED
    more than 50 ms off."""
    rng = np.random.default_rng(seed)
    for case in range(8):
        piece, stored = taught(styles[case % len(styles)], int(rng.integers(1, 100)))
        deck = Deck(speed=float(rng.uniform(0.94, 1.06)), wow=0.002, snr_db=20.0, start=0.0,
                    seconds=20.0, sample_rate=11025, seed=case)
        track, _, err = track_of(piece, stored, deck, 0.0)
        t = np.arange(len(err)) * T
        within = np.mean(np.abs(err[t >= 1.0]) <= 0.05)
        assert within >= share, (case, within)
        locked = np.flatnonzero(track.state == LOCKED)
        assert len(locked) and t[locked[0]] <= lock_by, (case, t[locked[:1]])
        assert np.all(np.abs(err[locked]) <= 0.05), (case, np.abs(err[locked]).max())


def test_a_cue_at_the_top_plays_from_the_first_frame_of_music():
    cue_at_the_top(("pop", "waltz", "techno"), 16)


def test_a_cue_at_the_top_of_slow_pads_never_locks_off():
    """Ambient pads: the lines through the cue fit at many rates, so the
    lock comes later (up to 8 s) and the tracker drifts before it; measured
    85-100 % within 50 ms (the target of 99 % is the xfail below)."""
    cue_at_the_top(("ambient",), 16, share=0.8, lock_by=10.0)


def test_music_from_the_first_frame_plays_from_the_cue_at_the_first_fit():
    """A tape whose music plays from its first frame (no leader): the cue's
    own line fit tells it at its first fit times (0.32 or 0.4 s of music),
    and the figure plays from the cue then, on the place; before, the
    follower waited 0.5 s for a leader that might form (measured 0.48-0.5 s
    on these decks, now 0.32-0.4 s). Twelve random decks, loudness alone."""
    rng = np.random.default_rng(16)
    for case in range(12):
        piece, stored = taught(("pop", "waltz", "techno")[case % 3], int(rng.integers(1, 100)))
        deck = Deck(speed=float(rng.uniform(0.94, 1.06)), wow=0.002, snr_db=20.0, start=0.0,
                    seconds=6.0, sample_rate=11025, seed=case)
        track, _, err = track_of(piece, stored, deck, 0.0)
        k = int(np.flatnonzero(track.state != WAITING)[0])
        assert k * T <= 0.4 + 1e-9, (case, k * T)
        assert abs(err[k]) <= 0.05, (case, err[k])


@pytest.mark.xfail(strict=True, reason="known gap: slow pads from the top reach 85-100 % within "
                   "50 ms, not 99 % (docs/music.md)")
def test_a_cue_at_the_top_of_slow_pads_meets_the_target():
    cue_at_the_top(("ambient",), 16)


def wrong_cue(styles, seed, later_s):
    """The tape starts 10-60 s into the piece, the cue says the top: no
    LOCKED tick more than 50 ms off, and the right place LOCKED at most
    later_s [s] later than from an unknown start."""
    rng = np.random.default_rng(seed)
    for case in range(8):
        piece, stored = taught(styles[case % len(styles)], int(rng.integers(1, 100)))
        deck = Deck(speed=float(rng.uniform(0.95, 1.05)), snr_db=20.0,
                    start=float(rng.uniform(10.0, 60.0)), seconds=20.0, sample_rate=11025, seed=case)
        track, _, err = track_of(piece, stored, deck, 0.0)
        locked = np.flatnonzero(track.state == LOCKED)
        assert np.all(np.abs(err[locked]) <= 0.05), (case, np.abs(err[locked]).max())
        unknown, _, err_unknown = track_of(piece, stored, deck, None)
        first = [np.flatnonzero((tr.state == LOCKED) & (np.abs(e) <= 0.05)) for tr, e in
                 ((track, err), (unknown, err_unknown))]
        cued_s, unknown_s = (x[0] * T if len(x) else np.inf for x in first)
        assert cued_s <= unknown_s + later_s, (case, cued_s, unknown_s)


def test_a_wrong_cue_is_refuted_without_a_false_lock():
    """Beside a pending cue the search is an unknown start's: measured no
    later than from an unknown start on these decks (0.8 s while the cue's
    line took a place in its pool, 2.9 s when a fitting measurement stopped
    it until the cue was refuted at 2 s)."""
    wrong_cue(("pop", "waltz", "techno"), 30, later_s=0.5)


@pytest.mark.xfail(strict=True, reason="known gap: in slow pads one deck locks 63 ms off after a "
                   "wrong cue (docs/music.md)")
def test_a_wrong_cue_in_slow_pads_is_refuted_without_a_false_lock():
    wrong_cue(("ambient",), 30, later_s=10.0)


def quiet_intro(piece, depth_db, fade_s):
    """The piece faded in from depth_db under over its first fade_s [s],
    after a 20 ms click 20 dB under its loud frames (so the cue's music
    starts at the first frame, as on the real recording hr3-caves)."""
    x = piece.samples.copy()
    n = int(fade_s * piece.sample_rate)
    x[:n] *= 10.0 ** (np.linspace(-depth_db, 0.0, n) / 20.0)
    loud = np.percentile(loudness(piece.samples, piece.sample_rate), 90)
    k = np.arange(int(0.02 * piece.sample_rate))
    x[:len(k)] = 0.1 * loud * np.sqrt(2.0) * np.sin(2.0 * np.pi * 1000.0 * k / piece.sample_rate)
    return replace(piece, samples=x)


def test_a_quiet_intro_under_the_hiss_does_not_refute_the_cue():
    """A fade-in from 35-45 dB down under 25-30 dB of hiss: a failing line
    through the cue is no evidence while the stored music lies under the
    hiss, so the cue holds at least as long as any hold does (lost_after)
    rather than being refuted at its 2 s fit; then the place is followed,
    never LOCKED off. Measured: the build before searched at 2 s in 7 of
    these 9 decks, this one from 4.1 s at the earliest (3 of 9)."""
    lost_after = OPTIONS["lost_after"]["default"]                # [s]
    rng = np.random.default_rng(44)
    for case in range(9):
        piece, _ = taught(("pop", "waltz", "techno")[case % 3], int(rng.integers(1, 100)))
        depth, fade = float(rng.uniform(35.0, 45.0)), float(rng.uniform(6.0, 10.0))     # [dB], [s]
        piece = quiet_intro(piece, depth, fade)
        stored = live_frames_of(piece.samples, piece.sample_rate)
        deck = Deck(speed=float(rng.uniform(0.95, 1.05)), snr_db=float(rng.uniform(25.0, 30.0)), start=0.0,
                    seconds=fade + 8.0, sample_rate=11025, seed=case)
        track, _, err = track_of(piece, stored, deck, 0.0)
        t = np.arange(len(err)) * T
        searching = t[track.state == SEARCHING]
        assert not np.any(searching < lost_after), (case, searching[:1])
        locked = track.state == LOCKED
        assert np.all(np.abs(err[locked]) <= 0.05), (case, np.abs(err[locked]).max())
        assert np.mean(np.abs(err[t >= fade + 1.0]) <= 0.05) >= 0.99, case


def leader_then_music(styles, seed, share):
    """A leader of hiss (the tape stands 1-3 s) before the music: the
    follower WAITS at the cue with rate 0, then follows from the onset:
    within 50 ms on `share` of the ticks from 1 s after it."""
    rng = np.random.default_rng(seed)
    for case in range(6):
        piece, stored = taught(styles[case % len(styles)], int(rng.integers(1, 100)))
        leader = float(rng.uniform(1.0, 3.0))
        cue = float(rng.choice([0.0, 20.0]))
        deck = Deck(speed=float(rng.uniform(0.96, 1.04)), snr_db=25.0, start=cue,
                    pauses=((0.0, leader),), seconds=leader + 10.0, sample_rate=11025, seed=case)
        track, _, err = track_of(piece, stored, deck, cue / T)
        t = np.arange(len(err)) * T
        before = t < leader - 0.1
        assert np.all(track.state[before] == WAITING), case
        assert np.all(track.position[before] == cue / T) and np.all(track.rate[before] == 0.0), case
        after = t >= leader + 1.0
        within = np.mean(np.abs(err[after]) <= 0.05)
        assert within >= share, (case, within)
        locked = np.flatnonzero(track.state == LOCKED)
        assert np.all(np.abs(err[locked]) <= 0.05), case


def test_silence_before_the_music_waits_at_the_cue():
    leader_then_music(("pop", "waltz", "techno"), 5, 0.98)


@pytest.mark.xfail(strict=True, reason="known gap: after a leader, slow pads are followed within "
                   "50 ms on 31-100 % of the ticks: the tracker drifts before the lock")
def test_silence_before_slow_pads_waits_at_the_cue():
    leader_then_music(("ambient",), 5, 0.9)


def test_the_engine_waits_in_its_start_pose_until_the_music_starts():
    """Engine(follow_start=...) in step mode: the commands stay at the show's
    pose at the cue while only hiss comes, and the show plays after."""
    piece, (loud, onset) = taught("waltz", 4)
    config = make_figure(2, max_speed=50.0, max_accel=5000.0)
    n = len(loud)
    x = np.array([0.3 * np.sin(2 * np.pi * 0.3 * np.arange(n) * T + j) for j in range(2)])
    show = Show(axis_names=config.axis_names, units=[a.unit for a in config.axes], positions=x,
                loudness=loud, onsets=onset, tick_period=T)
    deck = Deck(speed=1.03, snr_db=25.0, start=10.0, pauses=((0.0, 2.0),), seconds=8.0,
                sample_rate=11025, seed=3)
    played = play(piece.samples, piece.sample_rate, deck)
    live_loud, live_onset = (sync_ticks(v) for v in live_frames_of(played.samples, played.sample_rate))
    with Engine(config, show, follow=True, follow_start=10.0, record=True) as engine:
        for k in range(len(played.truth)):
            if not np.isnan(live_loud[k]):
                engine.push_loudness(live_loud[k], live_onset[k])
            engine.step(1)
        r = engine.records()
    t = np.arange(len(r)) * T
    wait = t < 1.9
    cue_tick = int(round(10.0 / T))
    np.testing.assert_array_equal(r["command"][wait], np.repeat(x[:, [cue_tick]].T, wait.sum(), axis=0))
    assert np.all(r["position"][wait] == cue_tick)
    err = r["position"] * T - played.truth
    assert np.mean(np.abs(err[t >= 3.0]) <= 0.05) >= 0.98


def test_paper_mode_plays_from_the_cue_in_whole_samples():
    """The paper's tracker doubles or skips whole stored samples: from a cue
    too, the position stays on whole samples, and from the lock on each tick
    steps 0, 1 or 2."""
    rng = np.random.default_rng(12)
    for case in range(4):
        piece, (loud, onset) = taught(("pop", "waltz", "techno")[case % 3], int(rng.integers(1, 100)))
        deck = Deck(speed=float(rng.uniform(0.96, 1.04)), snr_db=20.0, start=0.0,
                    pauses=((0.0, 1.0),), seconds=12.0, sample_rate=11025, seed=case)
        played = play(piece.samples, piece.sample_rate, deck)
        live_loud, live_onset = live_frames_of(played.samples, played.sample_rate)
        f = Follower(loud, onset=onset, mode="paper")
        f.cue(0.0)
        track = f.run(sync_ticks(live_loud)[:len(played.truth)], sync_ticks(live_onset)[:len(played.truth)])
        playing = track.state != WAITING
        assert np.any(playing), case
        assert np.all(track.position[playing] == np.round(track.position[playing])), case
        locked = np.flatnonzero(track.state == LOCKED)
        assert len(locked), case
        steps = np.diff(track.position[locked[0] + 1:])       # the line is placed until the lock
        assert set(np.unique(steps)) <= {0.0, 1.0, 2.0}, (case, set(np.unique(steps)))


def test_a_start_outside_the_music_is_refused_by_name(tmp_path):
    """follow_start / --start past the end (or negative) is a clear error,
    exit status 2 from the command, never a clamped cue."""
    piece, (loud, onset) = taught("pop", 3)
    config = make_figure(1)
    show = Show(axis_names=config.axis_names, units=["m"], positions=np.zeros((1, len(loud))),
                loudness=loud, onsets=onset, tick_period=T)
    end = len(loud) * T                                                      # [s]
    for start in (-1.0, end + 0.5, float("nan")):
        with pytest.raises(ValueError, match=f"follow_start {start!r} s is outside the taught music"):
            Engine(config, show, follow=True, follow_start=start)
    wav = tmp_path / "music.wav"
    write_wav(wav, piece.samples, int(piece.sample_rate))
    result = run_cli("sync-sim", "--taught", wav, "--live", wav, "--out", tmp_path / "t.csv",
                     "--start", f"{end + 10:g}")
    assert result.returncode == 2 and "Traceback" not in result.stderr, result.stderr
    assert f"--start {end + 10:g} s is outside the taught music [0, {end:g}] s" in result.stderr
