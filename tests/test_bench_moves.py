"""marionette bench moves: a short run gives the documented keys and sane figures."""
import json

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
