"""The numpy reference tick against the C engine, and smoke tests of the benchmarks.

The reference (marionette.bench.reference) mirrors ext/mar_sample.c,
ext/mar_limits.c and mar_engine_tick operation for operation, so on random
figures, shows, rates, lead modes and interpolations the commands [unit]
must agree; they are expected to agree bit for bit, the test allows 1e-9
relative (of the axis's position range, or of the value when larger).
"""
from __future__ import annotations

import functools
import json
import os
import shutil

import numpy as np
import pytest

from marionette import Engine
from marionette.bench import jitter, reference, tick
from marionette.config import config_from_dict, load_config
from marionette.demo import DEMO_SHOW
from marionette.show import Show, load_show

SEED = 20261122
N_CASES = 64
REL_TOL = 1e-9


def random_case(rng: np.random.Generator, index: int) -> dict:
    """A random figure, show and playback script (rates, seeks) for one case."""
    n_axes = int(rng.integers(1, 7))
    n_ticks = int(rng.choice([1, 2, 3, int(rng.integers(4, 12)), int(rng.integers(12, 60)),
                              int(rng.integers(12, 60)), int(rng.integers(20, 80)),
                              int(rng.integers(20, 80))]))             # [show ticks]
    period = float(rng.choice([0.02, 0.01, rng.uniform(0.001, 0.05)]))     # [s]
    huge = index % 16 == 15      # limits near the float range: overflow, non-finite targets
    axes, positions = [], np.empty((n_axes, n_ticks))
    for j in range(n_axes):
        if huge:
            lo, hi = -1.7e308, 1.7e308                                   # [unit]
        else:
            lo = float(rng.uniform(-2.0, 0.5))
            hi = lo + float(rng.uniform(0.05, 3.0))
        span = min(hi - lo, 1e300)                    # [unit], kept finite for the huge figures
        tight = rng.random() < 0.5                    # limiter busy, or mostly idle
        max_speed = float(rng.uniform(0.05, 2.0) * span if tight else 1e3 * span)    # [unit/s]
        max_accel = float(rng.uniform(0.1, 20.0) * span if tight else 1e6 * span)    # [unit/s^2]
        shape = rng.choice(["smooth", "rough", "edges"])
        if huge:
            x = rng.choice([-1.6e308, 1.6e308, 0.0], n_ticks)
        elif shape == "smooth":
            t = np.arange(n_ticks) * period
            x = 0.5 * (lo + hi) + 0.45 * (hi - lo) * np.sin(2 * np.pi * rng.uniform(0.2, 3.0) * t
                                                           + rng.uniform(0, 2 * np.pi))
        elif shape == "rough":
            x = rng.uniform(lo, hi, n_ticks)
        else:                                        # exactly on the limits, often
            x = rng.choice([lo, hi, 0.5 * (lo + hi)], n_ticks)
        positions[j] = np.clip(x, lo, hi)
        axes.append(dict(name=f"axis{j}", node=1 + j // 4, channel=j % 4, unit=["m", "rad"][j % 2],
                         min=lo, max=hi, home=float(positions[j, 0]),
                         max_speed=max_speed, max_accel=max_accel,
                         dead_time=float(rng.choice([0.0, rng.uniform(0.0, 0.15)])),       # [s]
                         time_constant=float(rng.choice([0.0, rng.uniform(0.0, 0.3)])),   # [s]
                         scale=1000.0))
    config = config_from_dict({"figure": {"name": f"case{index}", "tick_period": period},
                               "axis": axes}, f"<case {index}>")
    show = Show(axis_names=config.axis_names, units=[a["unit"] for a in axes],
                positions=positions, loudness=rng.uniform(0.0, 1.0, n_ticks), tick_period=period)
    rates = [0.0, 0.5, 1.0, 2.0, 0.37, float(rng.uniform(0.0, 3.0))]          # [show ticks per tick]
    script = []                                      # (ticks to step, then rate or seek)
    for _ in range(int(rng.integers(1, 4))):
        script.append((int(rng.integers(1, n_ticks + 8)),
                       ("rate", float(rng.choice(rates))) if rng.random() < 0.6
                       else ("seek", float(rng.uniform(0.0, n_ticks - 1)))))
    return dict(config=config, show=show, lead=str(rng.choice(reference.LEADS)),
                interpolation=str(rng.choice(reference.INTERPOLATIONS)),
                rate=float(rng.choice(rates)), script=script)


CASES = [random_case(np.random.default_rng([SEED, i]), i) for i in range(N_CASES)]


@functools.lru_cache(maxsize=None)
def run_both(index: int) -> tuple[np.ndarray, np.ndarray, list]:
    """C engine records and reference commands (ticks, axes) [unit] for one case."""
    case = CASES[index]
    kw = dict(lead=case["lead"], interpolation=case["interpolation"], rate=case["rate"])
    ref = reference.ReferenceEngine(case["config"], case["show"], **kw)
    ref_commands, ref_extra = [], []
    with Engine(case["config"], case["show"], record=True, **kw) as engine:
        for n, (what, value) in case["script"]:
            engine.step(n)
            for _ in range(n):
                ref_commands.append(ref.tick().copy())
                ref_extra.append((ref.position, ref.rate, int(ref.limited.sum()), ref.stored_loudness))
            getattr(engine, "set_rate" if what == "rate" else "seek")(value)
            getattr(ref, "set_rate" if what == "rate" else "seek")(value)
        engine.step(5)
        for _ in range(5):
            ref_commands.append(ref.tick().copy())
            ref_extra.append((ref.position, ref.rate, int(ref.limited.sum()), ref.stored_loudness))
        records = engine.records()
    return records, np.array(ref_commands), ref_extra


@pytest.mark.parametrize("index", range(N_CASES))
def test_reference_matches_engine(index):
    case = CASES[index]
    records, ref_commands, ref_extra = run_both(index)
    ours = records["command"]
    assert ours.shape == ref_commands.shape
    span = np.array([min(a.max - a.min, 1e300) for a in case["config"].axes])  # [unit]
    scale = np.maximum(np.abs(ref_commands), span)
    both_nan = np.isnan(ours) & np.isnan(ref_commands)
    close = both_nan | (np.abs(ours - ref_commands) <= REL_TOL * scale)
    assert close.all(), (f"case {index} ({case['lead']}, {case['interpolation']}): first mismatch "
                         f"at tick, axis {np.argwhere(~close)[0]}: engine "
                         f"{ours[~close][0]!r}, reference {ref_commands[~close][0]!r}")
    position, rate, limited, loudness = (np.array(v) for v in zip(*ref_extra))
    np.testing.assert_array_equal(records["position"], position)
    np.testing.assert_array_equal(records["rate"], rate)
    np.testing.assert_array_equal(records["stored_loudness"], loudness)
    if np.array_equal(ours, ref_commands, equal_nan=True):   # limited flags follow exact agreement
        np.testing.assert_array_equal(records["limited_axes"], limited)


def test_reference_is_bit_exact_on_the_cases():
    """What we see on x86-64 with gcc -O2 (no FMA contraction under -std=c11):
    every command of every case equal bit for bit."""
    inexact = [i for i in range(N_CASES)
               if not np.array_equal(run_both(i)[0]["command"], run_both(i)[1], equal_nan=True)]
    assert inexact == []


def test_cases_cover_the_modes():
    leads = {c["lead"] for c in CASES}
    interps = {c["interpolation"] for c in CASES}
    assert leads == set(reference.LEADS) and interps == set(reference.INTERPOLATIONS)
    assert any(c["show"].n_ticks == 1 for c in CASES) and any(c["show"].n_ticks == 2 for c in CASES)


def test_limit_step_refuses_non_finite_targets():
    x0 = np.zeros(3)
    v0 = np.array([1.0, -1.0, 0.0])                                  # [unit/s]
    target = np.array([np.nan, np.inf, -np.inf])
    one = np.ones(3)
    x1, v1, limited = reference.limit_step(-one, one, 10 * one, 100 * one, 0.02, x0, v0, target)
    assert limited.all()
    assert np.all(np.abs(x1) <= 1.0) and np.all(np.isfinite(v1))
    assert np.all(np.abs(v1) <= np.abs(v0))                          # slowing down to rest


def test_sample_holds_the_ends():
    x = np.array([[0.0, 1.0, 4.0, 9.0]])
    for interp in reference.INTERPOLATIONS:
        for p, want in ((-1.0, 0.0), (np.nan, 0.0), (3.0, 9.0), (7.5, 9.0), (1.0, 1.0), (2.0, 4.0)):
            value, slope = reference.sample(x, np.array([p]), interp)
            assert value[0] == want and (slope[0] == 0.0 or 0.0 < p < 3.0)


TICK_KEYS = {"axes", "median_us", "p999_us", "reference_median_us", "speedup"}
STAT_KEYS = {"p50_us", "p99_us", "p999_us", "max_us", "overruns"}


def test_tick_bench_quick_json(capsys):
    assert tick.main(["--json", "--quick"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert isinstance(rows, list) and [r["axes"] for r in rows] == list(tick.SIZES)
    for row in rows:
        assert TICK_KEYS <= set(row)
        assert row["median_us"] > 0 and row["p999_us"] >= row["median_us"]
        assert row["reference_median_us"] > 0 and row["speedup"] > 0
        assert row["max_abs_diff"] == 0.0
        assert "cpu" in row["machine"]


def test_tick_bench_table(capsys):
    assert tick.main(["--quick", "--axes", "16"]) == 0
    out = capsys.readouterr().out
    assert "median_us" in out and ("PASS" in out or "FAIL" in out)


def test_jitter_bench_json(capsys):
    assert jitter.main(["--json", "--seconds", "1", "--rounds", "2"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert {"engine", "cyclictest", "engine_gil_load", "machine", "seconds"} <= set(out)
    assert out["seconds"] == 1
    for key in ("engine", "engine_gil_load"):
        assert STAT_KEYS <= set(out[key])
        assert 0 <= out[key]["p50_us"] <= out[key]["p99_us"] <= out[key]["max_us"]
        assert out[key]["count"] == 50
    if shutil.which("cyclictest") is None:
        assert out["cyclictest"] is None and "not found" in out["cyclictest_note"]
    elif out["cyclictest"] is None:             # only without the right to SCHED_FIFO
        assert os.geteuid() != 0 and out["cyclictest_note"].startswith("failed")
    else:
        assert STAT_KEYS <= set(out["cyclictest"])
        assert out["cyclictest"]["count"] == 50
        assert 0 <= out["cyclictest"]["p50_us"] <= out["cyclictest"]["max_us"]


def test_histogram_quantiles_in_python_follow_the_c_rule(rng):
    """The jitter bench merges rounds in Python; on one histogram its
    quantiles must equal the C engine's own."""
    config = load_config()
    with Engine(config, load_show(DEMO_SHOW, config)) as engine:
        engine.step(3000)
        stats = engine.stats()["compute"]
        lower, width, counts, peak = engine.histogram("compute")
    assert int(counts.sum()) == stats["count"] == 3000
    for name, q in (("p50", 0.5), ("p99", 0.99), ("p999", 0.999)):
        assert jitter._hist_quantile(lower, width, counts, peak, q) / 1e3 == stats[f"{name}_us"]
    merged = jitter.merge_engine_runs([
        {"_histogram": (lower, width, counts, peak), "overruns": 1, "compute_p99_us": 1.0, "warnings": []},
        {"_histogram": (lower, width, counts, peak), "overruns": 2, "compute_p99_us": 2.0, "warnings": []}])
    assert merged["count"] == 6000 and merged["overruns"] == 3
    assert merged["p99_us"] == stats["p99_us"] and merged["max_us"] == peak / 1e3
