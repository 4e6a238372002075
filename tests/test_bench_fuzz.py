"""`marionette bench fuzz`: a short run's report, and its statistics."""
import json
import math

import pytest

from conftest import run_cli
from marionette.bench import fuzz

FRAMES = 20000


@pytest.fixture(scope="module")
def report():
    return fuzz.collect(FRAMES, seed=fuzz.SEED)


def test_short_run_reports_every_field(report):
    for key in ("frames", "clean", "clean_lost", "mutated", "crc_trials", "mutated_rejected",
                "mutated_same", "accepted_corrupt", "crc16_accepted", "low_weight",
                "low_weight_accepted", "garbage_runs", "garbage_bytes", "garbage_accepted",
                "wire_bytes", "can_frames", "can_messages", "seconds", "frames_per_s",
                "wire_mb_per_s", "crashed", "hung", "expected_accepted", "bound_accepted",
                "expected_crc16", "bound_crc16", "checks", "passed", "machine", "seed"):
        assert key in report, key
    assert report["frames"] == FRAMES and not report["crashed"] and not report["hung"]
    assert report["frames_per_s"] > 1000 and report["seconds"] < 30
    # every kind of case ran, in about the planned shares (10/10/15/65 %)
    assert report["clean"] + report["mutated"] + report["low_weight"] == FRAMES
    assert abs(report["low_weight"] / FRAMES - 0.15) < 0.02 and abs(report["mutated"] / FRAMES - 0.65) < 0.02
    assert report["garbage_runs"] > 0.08 * FRAMES and report["can_frames"] > FRAMES / 4
    assert report["crc_trials"] > 0.05 * FRAMES
    assert report["clean_lost"] == 0 and report["low_weight_accepted"] == 0
    assert report["mutated_rejected"] + report["mutated_same"] <= report["mutated"]
    assert report["passed"], report["checks"]


def test_accepted_corrupt_within_the_binomial_bound(report):
    n = report["crc_trials"]
    assert report["expected_accepted"] == pytest.approx(n * 2.0 ** -32)
    assert report["accepted_corrupt"] <= fuzz.binomial_upper(n, 2.0 ** -32) <= 1
    assert report["crc16_accepted"] <= fuzz.binomial_upper(n, 2.0 ** -16)


def test_same_seed_same_report(report):
    again = fuzz.collect(FRAMES, seed=fuzz.SEED)
    skip = {"seconds", "frames_per_s", "wire_mb_per_s", "machine"}
    assert {k: v for k, v in again.items() if k not in skip} == \
        {k: v for k, v in report.items() if k not in skip}
    other = fuzz.collect(2000, seed=1)
    assert other["garbage_bytes"] != report["garbage_bytes"]


def test_binomial_upper_bound():
    # P(X > k) <= alpha at the bound, and not at one less
    def tail(n, p, k):
        return 1.0 - sum(math.comb(n, i) * p ** i * (1 - p) ** (n - i) for i in range(k + 1))
    for n, p in [(1000, 0.01), (20000, 2.0 ** -16), (50, 0.5), (10**6, 2.0 ** -32)]:
        k = fuzz.binomial_upper(n, p)
        assert tail(n, p, k) <= fuzz.ALPHA + 1e-12
        assert k == 0 or tail(n, p, k - 1) > fuzz.ALPHA
    assert fuzz.binomial_upper(0, 0.5) == 0


def test_the_verdict_fails_what_it_should(report):
    for key, value in [("accepted_corrupt", 5), ("low_weight_accepted", 1), ("clean_lost", 1),
                       ("crashed", True), ("hung", True), ("crc16_accepted", 10**6)]:
        bad = fuzz.evaluate(dict(report, **{key: value}))
        assert not bad["passed"], key


def test_cli_json():
    result = run_cli("bench", "fuzz", "--frames", "3000", "--seed", "5", "--json")
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    assert out["frames"] == 3000 and out["seed"] == 5 and out["passed"]
    text = run_cli("bench", "fuzz", "--frames", "1000")
    assert text.returncode == 0 and "accepted corrupt" in text.stdout and "FAIL" not in text.stdout
    assert run_cli("bench", "fuzz", "--frames", "0").returncode == 2
