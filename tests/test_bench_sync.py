"""marionette bench sync: a quick run gives the documented keys for both
modes and the cue's sets of runs; the figures are computed the documented
way (checked on made-up tracks whose errors are known), and a bad cued run
is reported as failing the cue's targets."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from marionette.bench import sync
from marionette.music.follower import STATES, Track
from marionette.sim.tape import Played

KEYS = {"mode", "within20", "within50", "within200", "median_ms", "p95_ms", "lock_s_max",
        "relock_after_pause_s_max", "false_locks", "us_per_tick_median", "us_per_tick_p99"}
LOCKED, SEARCHING, PAUSED = (STATES.index(s) for s in ("locked", "searching", "paused"))


SETS = [("smooth", "unknown"), ("paper", "unknown"), ("smooth", "cue at top"),
        ("smooth", "top, unknown"), ("smooth", "wrong cue"), ("smooth", "wrong cue, unknown")]


def labels(targets):
    return {f"{k} {op} {b:g}" for k, op, b in targets}


@pytest.fixture(scope="module")
def quick_results():
    """One quick run, shared: the table and --strict tests format it again."""
    return sync.collect(quick=True, seeds=1)


def test_quick_run_has_the_documented_keys(capsys, tmp_path):
    assert sync.main(["--json", "--quick", "--music-dir", str(tmp_path)]) == 0     # no recordings
    results = json.loads(capsys.readouterr().out)
    assert [(r["mode"], r["start"]) for r in results] == SETS
    for r in results:
        assert KEYS <= set(r)
        assert 0.0 <= r["within20"] <= r["within50"] <= r["within200"] <= 1.0
        assert r["us_per_tick_median"] > 0 and r["us_per_tick_p99"] >= r["us_per_tick_median"]
        assert "machine" in r
    by_set = {(r["mode"], r["start"]): r for r in results}
    for key in SETS[:4]:                        # two scenarios and their top variants
        assert len(by_set[key]["scenarios"]) == 2
    assert [s["start_s"] for s in by_set["smooth", "cue at top"]["scenarios"]] == [0.0, 0.0]
    assert [s["start_s"] for s in by_set["smooth", "unknown"]["scenarios"]] != [0.0, 0.0]
    assert len(by_set["smooth", "wrong cue"]["scenarios"]) == 1
    assert 10.0 <= by_set["smooth", "wrong cue"]["scenarios"][0]["start_s"] <= 60.0
    assert {"cue_lock_s_max", "cue_lock_s_median"} <= set(by_set["smooth", "cue at top"])
    assert {"later_s_max", "later_s_median"} <= set(by_set["smooth", "wrong cue"])
    assert set(results[0]["targets"]) == labels(sync.TARGETS)
    assert set(by_set["smooth", "cue at top"]["targets"]) == labels(sync.CUE_TARGETS)
    assert set(by_set["smooth", "wrong cue"]["targets"]) == labels(sync.WRONG_CUE_TARGETS)
    assert by_set["smooth", "top, unknown"]["targets"] == {}


def without_cost(x):
    """A result with the cost per tick (which depends on the machine's load) left out."""
    if isinstance(x, dict):
        return {k: without_cost(v) for k, v in x.items() if not k.startswith("us_per_tick")}
    if isinstance(x, list):
        return [without_cost(v) for v in x]
    return x


def test_decks_played_at_once_give_the_same_figures(quick_results):
    """--jobs 2 plays the decks in two processes: every figure but the cost
    per tick is the same as one after the other, deck by deck and in order."""
    at_once = sync.collect(quick=True, seeds=1, jobs=2)
    assert [r.pop("jobs") for r in at_once] == [2] * len(SETS)
    one = json.dumps(without_cost(quick_results), default=float)
    assert json.dumps(without_cost(at_once), default=float) == one
    assert all(r["us_per_tick_median"] > 0 for r in at_once)


def test_table_names_targets_and_machine(quick_results):
    out = sync.format_table(quick_results)
    assert "machine:" in out and "targets, synthesized pieces (smooth mode" in out
    assert ("all targets met" in out) or ("FAILED" in out)
    for key, op, bound in sync.TARGETS + sync.CUE_TARGETS + sync.WRONG_CUE_TARGETS:
        assert f"{key} {op} {bound:g}" in out
    assert "targets, cue at top" in out and "targets, wrong cue" in out
    assert "top decks, cued at the top (every tick)" in out
    # a scenario: smooth and paper rows, and its top variant cued and not;
    # the wrong-cue deck: one row
    assert out.count("pop/pauses ") == 4 and out.count("pop/wrong1 ") == 1


def test_strict_exits_1_when_a_target_fails(quick_results, monkeypatch, capsys, tmp_path):
    results = [dict(r, targets=dict(r["targets"])) for r in quick_results]
    for r in results:
        r["targets"] = {k: True for k in r["targets"]}
    monkeypatch.setattr(sync, "collect", lambda *a, **k: results)
    argv = ["--quick", "--music-dir", str(tmp_path)]           # no recordings: their targets skipped
    assert sync.main(argv + ["--strict"]) == 0
    cue = next(r for r in results if r["start"] == "cue at top")
    cue["targets"]["false_locks <= 0"] = False
    assert sync.main(argv + ["--strict"]) == 1
    assert sync.main(argv) == 0                                # without --strict: a report only
    cue["targets"]["false_locks <= 0"] = True
    cue["real"] = dict(cue, targets={"false_locks <= 0": False})    # a real recording's target fails
    assert sync.main(argv + ["--strict"]) == 1
    capsys.readouterr()


def test_seconds_must_be_sensible(capsys):
    assert sync.main(["--seconds", "2"]) == 2
    assert "--seconds" in capsys.readouterr().err


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
    from marionette.sim.tape import Deck, play
    x = np.sin(np.arange(16000 * 12) * 0.05) * 0.1
    played = play(x, 16000, Deck(pauses=((1.0, 2.0), (2.5, 3.0)), seconds=8.0))
    assert played.resumes == [pytest.approx(5.5)]             # not at 3.0: the second pause holds it
    assert played.paused[int(4.0 / 0.02)] and not played.paused[int(5.6 / 0.02)]


def cued_run(err, state, onset_s=0.0):
    """A cued run's figures (from 1 s after the onset, lock within 50 ms)."""
    return sync.measure(*made_up(err, state), from_s=onset_s + sync.CUE_FROM_S, onset_s=onset_s)


def test_a_good_cued_run_meets_the_cue_targets():
    n = 1000                                                  # 20 s
    err = np.zeros(n)
    state = np.full(n, LOCKED)
    state[:20] = SEARCHING                                    # LOCKED from 0.4 s on
    err[:20] = 0.3                                            # searching: wherever
    s = sync.summarize([cued_run(err, state)])
    assert s["cue_lock_s_max"] == pytest.approx(0.4)
    assert s["within50"] == 1.0 and s["false_locks"] == 0
    assert all(ok for _, _, ok in sync.check_targets(s, sync.CUE_TARGETS))


def test_a_bad_cued_run_fails_the_cue_targets():
    n = 1000                                                  # 20 s, the onset at 0
    err = np.zeros(n)
    state = np.full(n, LOCKED)
    state[:40] = SEARCHING                                    # the cue's fits: 0.8 s
    err[:40] = 0.03                                           # at the right place, not LOCKED
    state[30:35] = LOCKED
    err[30:35] = 2.0                                          # LOCKED 2 s off at 0.6 s: a false lock
    err[100:120] = 0.1                                        # 20 ticks 100 ms off after the first second
    m = cued_run(err, state)
    s = sync.summarize([m])
    assert m["cue_lock_s"] == pytest.approx(0.8)              # the first LOCKED tick within 50 ms
    assert s["false_locks"] == 1
    assert s["within50"] == pytest.approx(1 - 20 / (n - 50))  # counted from 1 s on
    failed = {label for label, _, ok in sync.check_targets(s, sync.CUE_TARGETS) if not ok}
    assert failed == labels(sync.CUE_TARGETS)                 # all three fail


def test_cue_accuracy_counts_from_a_second_after_the_onset():
    n = 500
    err = np.zeros(n)
    err[:100] = 1.0                                           # 2 s wrong: the onset is at 1 s
    state = np.full(n, LOCKED)
    m = cued_run(err, state, onset_s=1.0)
    assert len(m["errors"]) == n - 100 and np.all(m["errors"] < 1e-9)
    assert m["cue_lock_s"] == pytest.approx(1.0)              # from the onset to 2.0 s


def test_a_wrong_cue_found_later_fails():
    n = 1500
    err = np.full(n, 20.0)                                    # the tape is 20 s from the cue
    state = np.full(n, SEARCHING)
    unknown_err, unknown_state = err.copy(), state.copy()
    unknown_err[150:], unknown_state[150:] = 0.0, LOCKED      # found at 3 s
    err[250:], state[250:] = 0.0, LOCKED                      # cued: found at 5 s
    cued = sync.measure(*made_up(err, state))
    unknown = sync.measure(*made_up(unknown_err, unknown_state))
    cued["later_s"] = sync.wrong_cue_later(cued, unknown)
    s = sync.summarize([cued])
    assert s["later_s_max"] == pytest.approx(2.0)
    targets = {label: ok for label, _, ok in sync.check_targets(s, sync.WRONG_CUE_TARGETS)}
    assert targets == {"later_s_max <= 0": False, "false_locks <= 0": True}
    never = sync.measure(*made_up(np.full(n, 20.0), np.full(n, SEARCHING)))
    assert sync.wrong_cue_later(never, unknown) == math.inf
    assert sync.wrong_cue_later(never, never) == 0.0
    assert sync.wrong_cue_later(unknown, never) == -math.inf


def test_a_missing_figure_fails_its_target():
    assert [ok for _, _, ok in sync.check_targets({}, sync.CUE_TARGETS)] == [False] * 3


def test_cue_decks():
    durations = {style: 100.0 for style, _ in sync.PIECES}
    runs = sync.scenarios(durations, None, False, 7)
    top = sync.top_variants(runs)
    assert [sc.deck.start for sc in top] == [0.0] * len(runs)
    for a, b in zip(runs, top):                               # the same deck otherwise
        assert {**a.deck.__dict__, "start": 0.0} == b.deck.__dict__ and a.target == b.target
    wrong = sync.wrong_cue_decks(durations, None, False, 7)
    assert len(wrong) == sync.WRONG_CUE_DECKS * len(sync.PIECES)
    assert all(10.0 <= sc.deck.start <= 60.0 and sc.target for sc in wrong)
    again = sync.wrong_cue_decks(durations, None, False, 7)
    assert [sc.deck for sc in wrong] == [sc.deck for sc in again]
    assert [sc.deck for sc in sync.scenarios(durations, None, False, 7)] == [sc.deck for sc in runs]
