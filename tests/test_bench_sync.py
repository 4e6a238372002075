"""marionette bench sync: a quick run gives the documented keys for both
modes; the figures are computed the documented way (checked on made-up
tracks whose errors are known)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from marionette.bench import sync
from marionette.bench.tape import Played
from marionette.follow import STATES, Track

KEYS = {"mode", "within20", "within50", "within200", "median_ms", "p95_ms", "lock_s_max",
        "relock_after_pause_s_max", "false_locks", "us_per_tick_median", "us_per_tick_p99"}
LOCKED, SEARCHING, PAUSED = (STATES.index(s) for s in ("locked", "searching", "paused"))


def test_quick_run_has_the_documented_keys(capsys):
    assert sync.main(["--json", "--quick"]) == 0
    results = json.loads(capsys.readouterr().out)
    assert [r["mode"] for r in results] == ["smooth", "paper"]
    for r in results:
        assert KEYS <= set(r)
        assert 0.0 <= r["within20"] <= r["within50"] <= r["within200"] <= 1.0
        assert r["us_per_tick_median"] > 0 and r["us_per_tick_p99"] >= r["us_per_tick_median"]
        assert len(r["scenarios"]) == 2 and "machine" in r
    assert set(results[0]["targets"]) == {f"{k} {op} {b:g}" for k, op, b in sync.TARGETS}


def test_table_names_targets_and_machine(capsys):
    assert sync.main(["--quick"]) == 0
    out = capsys.readouterr().out
    assert "machine:" in out and "targets (smooth mode" in out
    assert ("all targets met" in out) or ("FAILED" in out)
    for key, op, bound in sync.TARGETS:
        assert f"{key} {op} {bound:g}" in out


def test_seconds_must_be_sensible():
    with pytest.raises(SystemExit):
        sync.main(["--seconds", "2"])


def made_up(errors_s, states, resumes=(), jumps=(), paused=None):
    """A track whose error against a straight truth is errors_s [s]."""
    n = len(errors_s)
    truth = 10.0 + np.arange(n) * sync.T
    track = Track(position=(truth + errors_s) / sync.T, rate=np.ones(n), confidence=np.ones(n),
                  state=np.asarray(states, dtype=np.int8), flags=np.zeros(n, np.uint32))
    played = Played(samples=np.zeros(0), sample_rate=16000.0, truth=truth,
                    paused=np.zeros(n, bool) if paused is None else paused,
                    resumes=list(resumes), jumps=list(jumps))
    return track, played


def test_figures_on_a_known_track():
    n = 1000                                                   # 20 s
    err = np.zeros(n)
    err[:250] = 5.0                                            # searching for 5 s
    err[500:510] = 0.03                                        # 10 ticks 30 ms off
    err[600:602] = 0.3                                         # 2 ticks 300 ms off
    state = np.full(n, LOCKED)
    state[:250] = SEARCHING
    m = sync.measure(*made_up(err, state), ns=np.full(n, 2000))
    s = sync.summarize([m])
    measured = n - 150                                         # from 3 s on: 100 searching ticks count
    assert s["within20"] == pytest.approx((measured - 112) / measured)
    assert s["within50"] == pytest.approx((measured - 102) / measured)
    assert s["within200"] == pytest.approx((measured - 102) / measured)
    assert s["lock_s_max"] == pytest.approx(5.0)
    assert s["false_locks"] == 0 and s["us_per_tick_median"] == pytest.approx(2.0)
    assert math.isnan(s["relock_after_pause_s_max"])
    targets = dict((label, ok) for label, _, ok in sync.check_targets({**s, "relock_after_pause_s_max": 0.1}))
    assert targets["within200 >= 1"] is False and targets["lock_s_max <= 3"] is False


def test_a_run_that_never_locks_counts_as_missed():
    n = 1000
    good = sync.measure(*made_up(np.zeros(n), np.full(n, LOCKED)))
    never = sync.measure(*made_up(np.full(n, 5.0), np.full(n, SEARCHING)))
    s = sync.summarize([good, never])
    assert s["within200"] == pytest.approx(0.5)                # not 1.0: the lost run is not dropped
    assert s["lock_s_max"] == math.inf


def test_false_locks_and_resume_times():
    n = 1500
    err = np.zeros(n)
    state = np.full(n, LOCKED)
    state[200:260] = SEARCHING
    err[260:300] = 4.0                                        # locked 4 s off: one false lock
    state[700:800] = PAUSED
    err[800:830] = 0.1                                        # after the pause: 0.6 s to within 50 ms
    m = sync.measure(*made_up(err, state, resumes=[16.0]))
    assert m["false_locks"] == 1
    assert m["relock_pause"] == [pytest.approx(0.6)]
    # every tick from 3 s on is measured but the 0.5 s after the resume;
    # the false lock's ticks count
    assert len(m["errors"]) == n - 150 - 25 and np.sum(m["errors"] > 1.0) == 40


def test_overlapping_pauses_restart_the_tape_once():
    from marionette.bench.tape import Deck, play
    x = np.sin(np.arange(16000 * 12) * 0.05) * 0.1
    played = play(x, 16000, Deck(pauses=((1.0, 2.0), (2.5, 3.0)), seconds=8.0))
    assert played.resumes == [pytest.approx(5.5)]             # not at 3.0: the second pause holds it
    assert played.paused[int(4.0 / 0.02)] and not played.paused[int(5.6 / 0.02)]
