"""marionette bench bands: the documented keys from a quick run through the
command, and its figures computed the documented way (a window taken from
the stored feature itself is found where it was cut; one cut from a piece
that repeats itself exactly is not)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from marionette.bench import bands as bench
from marionette.bench import bands_cue
from marionette.cli import main

KEYS = {"section", "feature", "window_s", "windows", "identified", "identified_clean", "lead_z_median",
        "lead_z_p10", "true_corr_median", "machine"}
CUE_KEYS = {"section", "feature", "lead_z", "decks_top", "decks_wrong", "locked_by_0_5s", "lock_s_median",
            "bad_locks", "wrong_false_locks", "machine"}
FEATURES = ["loudness"] + [f"bands{n}" for n in bench.BAND_COUNTS]


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    return bench.collect(quick=True)


def test_quick_run_through_the_command_has_the_documented_keys(capsys, monkeypatch, quick):
    monkeypatch.setattr(bench, "collect", lambda **kw: quick)    # the runs themselves: the fixture's
    assert main(["bench", "bands", "--quick", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    identify = [r for r in rows if r["section"] == "identify"]
    cue = [r for r in rows if r["section"] == "cue"]
    assert len(identify) + len(cue) == len(rows)
    assert {(r["feature"], r["window_s"]) for r in identify} == {(f, s) for f in FEATURES for s in bench.WINDOW_S}
    for r in identify:
        assert KEYS <= set(r)
        assert r["windows"] > 50 and 0.0 <= r["identified"] <= 1.0
    assert {(r["feature"], r["lead_z"]) for r in cue} == {(f, z) for f in FEATURES for z in bands_cue.LEAD_Z}
    for r in cue:
        assert CUE_KEYS <= set(r)
        assert r["decks_top"] >= 3 and r["decks_wrong"] >= 1


def test_bands_tell_half_a_second_of_music_from_its_other_places_more_often(quick):
    by = {(r["feature"], r["window_s"]): r for r in quick if r["section"] == "identify"}
    assert by["bands6", 0.5]["identified"] > by["loudness", 0.5]["identified"] + 0.1
    assert by["bands6", 2.0]["identified"] >= by["loudness", 2.0]["identified"]


def test_a_window_of_the_stored_feature_is_found_where_it_was_cut_unless_the_music_repeats():
    rng = np.random.default_rng(3)
    stored = rng.normal(size=(3000, 4)).cumsum(axis=0) * 0.3        # a wandering level per band [dB]
    truth = np.arange(3000) * bench.T
    rows = bench.measure_deck(stored, stored, truth, np.random.default_rng(4))
    assert all(ok for secs in bench.WINDOW_S for ok, _, _ in rows[secs])
    looped = np.concatenate([stored[:1000]] * 3)                    # the same 20 s three times
    rows = bench.measure_deck(looped, looped, truth, np.random.default_rng(4))
    assert not any(ok for secs in bench.WINDOW_S for ok, _, _ in rows[secs])


def test_correlations_match_the_direct_formula_at_every_offset():
    rng = np.random.default_rng(5)
    stored, live = rng.normal(size=(200, 3)), rng.normal(size=(20, 3))
    from marionette.music.bands import window_correlation
    direct = [window_correlation(live, stored[o:o + 20]) for o in range(181)]
    assert np.allclose(bench.correlations(live, stored), direct)


def test_the_cue_decision_finds_the_line_of_a_tape_from_the_top_and_refuses_another_place():
    """A wandering level in 4 bands is the stored piece; heard from the top
    on a tape at 1.03, the best line through the cue has that rate and beats
    every other place; heard from 20 s in, some other place beats the cue."""
    rng = np.random.default_rng(6)
    stored = rng.normal(size=(3000, 4)).cumsum(axis=0) * 0.3                 # [dB]
    rate, heard = 1.03, 60                                                    # [1], [frames]
    t = np.arange(heard) * rate                                               # stored frame of each live frame
    live = np.stack([np.interp(t, np.arange(3000), stored[:, b]) for b in range(4)], axis=1)
    corr, elsewhere, fitted, d = bands_cue.cue_decision(stored, live, 0, heard)
    assert abs(fitted - rate) <= 0.005 and d == 0 and corr > 0.99 and corr > elsewhere
    away = stored[1000:1000 + heard]
    corr, elsewhere, _, _ = bands_cue.cue_decision(stored, away, 0, heard)
    assert elsewhere > corr
