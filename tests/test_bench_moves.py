"""marionette bench moves: a short run gives the documented keys and sane figures."""
import json
import sys

import numpy as np

from marionette.bench import moves

KEYS = {"cases", "duration_ratio_median", "duration_ratio_max", "violations", "us_per_call_median",
        "ruckig_us_per_call_median", "climax_error_ticks_max_compensated",
        "climax_error_ticks_max_uncompensated"}


def test_quick_run_has_the_documented_keys(capsys):
    assert moves.main(["--json", "--quick"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert KEYS <= set(result)
    assert result["cases"] == 200 and result["violations"] == 0
    assert result["climax_error_ticks_max_compensated"] < result["climax_error_ticks_max_uncompensated"]
    if result["duration_ratio_max"] is not None:                 # ruckig installed
        assert result["duration_ratio_max"] <= 1.001


def test_violation_check_catches_a_broken_profile():
    x0, v0, target, vmax, amax = moves.random_cases(1, seed=5)[0]
    assert not moves.violates(x0, v0, target, vmax, amax, moves.plan_move(x0, v0, target, vmax, amax)[0])
    # a profile cut short of its duration does not end at rest on the target
    d = moves.plan_move(x0, v0, target, vmax, amax)[0]
    assert moves.violates(x0, v0, target, vmax, amax, d * 0.5)          # not at the target yet
    cases = moves.random_cases(50, seed=6)
    assert np.all(np.abs(cases[:, 1]) <= cases[:, 3])


def test_without_ruckig_the_comparison_is_skipped_not_failed(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ruckig", None)          # as when it is not installed
    assert moves.main(["--quick", "--strict"]) == 0
    out = capsys.readouterr().out
    assert "ruckig: not installed" in out
    assert "duration_ratio_max <= 1.001" in out and "SKIPPED" in out and "FAIL" not in out
    assert moves.main(["--quick", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["targets"]["duration_ratio_max <= 1.001"] is None


def test_strict_means_the_same_in_every_bench():
    from marionette.bench import exit_status, verdict
    assert [verdict(ok) for ok in (True, False, None)] == ["PASS", "FAIL", "SKIPPED"]
    assert exit_status([True, None], strict=True) == 0
    assert exit_status([True, False, None], strict=True) == 1
    assert exit_status([False], strict=False) == 0
    from marionette.cli import build_parser
    bench = next(a for a in build_parser()._actions if a.dest == "command").choices["bench"]
    with_targets = {"tick", "jitter", "moves", "fuzz", "sync", "shape", "console-cost"}
    for name, parser in next(a for a in bench._actions if a.dest == "bench").choices.items():
        strict = [a for a in parser._actions if "--strict" in a.option_strings]
        assert bool(strict) == (name in with_targets), name
        if strict:
            assert "measured" in strict[0].help, name
