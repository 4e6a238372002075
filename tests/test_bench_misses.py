"""`marionette bench misses`: each missed tick put down to one cause, on made-up tracks and on the bench's decks."""
import json

import numpy as np
from conftest import run_cli
from marionette.bench import misses
from marionette.bench import sync as bs
from marionette.sim.tape import Played

T = misses.T


def played(n, paused=(), resumes=(), jumps=()):
    p = np.zeros(n, bool)
    for a, b in paused:
        p[a:b] = True
    return Played(samples=np.zeros(1), sample_rate=16000.0, truth=np.arange(n) * T, paused=p,
                  resumes=list(resumes), jumps=list(jumps))


def test_a_stop_under_the_hiss_is_masked_and_a_stop_out_of_loud_music_is_not():
    rng = np.random.default_rng(5)
    for _ in range(50):
        n = 400
        a = int(rng.integers(50, 150)); b = a + int(rng.integers(20, 100))
        c = b + int(rng.integers(30, 60)); d = c + int(rng.integers(20, 100))
        hiss = -40.0
        level = hiss + rng.normal(0, 0.5, n)
        level[:a] += 1.0                          # music at the hiss before the first stop
        level[b:c] += 20.0                        # loud music before the second
        m = misses.masked_stops(level, played(n, [(a, b), (c, d)]).paused)
        assert m[a:b].all() and not m[c:d].any() and not m[:a].any() and not m[b:c].any()


def test_each_missed_tick_has_one_cause():
    rng = np.random.default_rng(9)
    for _ in range(50):
        n = 600
        a = int(rng.integers(50, 200)); b = a + int(rng.integers(20, 80))   # a masked stop
        jump = int(rng.integers(b + 100, 500))
        pl = played(n, [(a, b)], resumes=[b * T], jumps=[jump * T])
        t = np.arange(n) * T
        err = np.zeros(n)
        err[a:b] = (np.arange(b - a) + 1) * T       # the flywheel runs on through the stop
        back = b + int(rng.integers(5, 30))          # the relock after the resume
        err[b:back] = 0.3
        back_j = jump + int(rng.integers(5, 60))
        err[jump:back_j] = 5.0
        stray = int(rng.integers(back + 1, jump - 1))
        err[stray] = 0.06                             # one miss of no event
        measured = np.ones(n, bool)
        level = np.full(n, -40.0)
        got = misses.causes(err, t, pl, level, measured)
        assert got["masked stop"] == int(np.sum(err[a:b] > misses.MISS_S))
        assert got["seen stop"] == 0
        assert got["relock after a resume"] == back - b
        assert got["relock after a jump"] == back_j - jump
        assert got["elsewhere"] == 1
        assert got["ticks"] == n and got["masked_ticks"] == b - a


def test_bench_misses_quick_runs_the_follower_on_the_bench_decks():
    r = run_cli("bench", "misses", "--quick", "--seeds", "1", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert set(out["kinds"]) == {"pauses", "jump"}
    assert out["total"]["ticks"] > 1000
    assert 0.5 < out["within50"] <= out["within50_without_masked"] <= 1.0


def test_the_decks_are_bench_syncs_cued_top_decks():
    """Every piece's decks, not only the first's: scenarios() draws for the
    pieces in turn (a draw over one piece alone gave other decks)."""
    durations = {"pop": 90.0, "waltz": 75.0, "ambient": 110.0, "techno": 160.0}      # [s]
    for seed in (3, 20261125):
        bench = bs.top_variants([sc for sc in bs.scenarios(durations, None, False, seed) if sc.target])
        for style in durations:
            got = misses.cued_top_decks(durations, style, seed)
            assert [sc.deck for sc in got] == [sc.deck for sc in bench if sc.piece == style]
            assert len(got) == 4 and all(sc.deck.start == 0.0 for sc in got)
