"""Smoke test of marionette.bench.climax: shaped climaxes on simulated servos."""
import json

from marionette.bench import climax

KEYS = ("climax_error_ticks_max_compensated", "climax_error_ticks_median_compensated",
        "climax_error_ticks_max_uncompensated", "climax_error_ticks_median_uncompensated")


def test_compensation_beats_none():
    r = climax.climax_timing(seconds=12.0)
    assert all(isinstance(r[k], float) for k in KEYS)
    assert r["climaxes"] > 50
    assert r["climax_error_ticks_max_compensated"] < r["climax_error_ticks_max_uncompensated"]
    assert r["climax_error_ticks_median_compensated"] < 0.25 * r["climax_error_ticks_median_uncompensated"]
    assert r["climax_error_ticks_max_compensated"] <= climax.TARGET_TICKS


def test_main_json(capsys):
    assert climax.main(["--json", "--seconds", "5"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert set(KEYS) <= set(r)
    assert climax.main(["--seconds", "5"]) == 0
    assert "dead_time_lag" in capsys.readouterr().out
