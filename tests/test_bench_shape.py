"""marionette bench shape: limited axis-ticks on shaped shows (goal 0) and climax timing."""
import json

from marionette.bench import shape


def test_one_random_taught_show(capsys):
    assert shape.main(["--json", "--count", "1", "--seconds", "6"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["demo"] > 0 and r["taught_unshaped_total"] > 0      # unshaped, the limits act
    assert r["demo_shaped"] == r["sample"] == r["taught_shaped_max"] == 0
    assert r["demo_shaped_rate_0.94"] == r["demo_shaped_rate_1.06"] == 0
    assert r["sample_followed_tape_0.97"] == r["sample_followed_tape_1.03"] == 0
    targets = r["targets"]
    assert targets["limited == 0 on every shaped show"]
    assert targets["limited == 0 at other rates and following"]
    # the servo's extremum: within a tick of every climax (each one a turn)
    assert r["climax_error_ticks_median_compensated"] < 0.05
    assert r["climax_error_ticks_max_compensated"] <= 1.0
    assert targets["climax_error_ticks_max_compensated <= 1"]
    assert r["alignment_error_ticks_max_compensated"] <= 1.0


def test_bad_options_exit_2(capsys):
    for argv in (["--count", "-1"], ["--seconds", "50"]):
        assert shape.main(argv) == 2
    err = capsys.readouterr().err
    assert "--count" in err and "--seconds" in err and "'50'" in err
