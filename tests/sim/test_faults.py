"""Fault injection: rates as asked for (binomial bounds), repeatable, and
the control commands' errors."""
import numpy as np
import pytest

from marionette.sim.faults import Faults


@pytest.mark.parametrize("seed", range(5))
def test_drop_and_corrupt_rates(seed):
    data = bytes(np.random.default_rng(seed).integers(0, 256, 200_000, dtype=np.uint8))
    f = Faults(drop_rate=0.01, corrupt_rate=0.002, seed=seed)
    out = f.mangle(data)
    n = len(data)
    for count, p in ((f.bytes_dropped, 0.01), (f.bytes_corrupted, 0.002)):
        assert abs(count - n * p) < 5 * np.sqrt(n * p * (1 - p)), (count, p)
    assert len(out) == n - f.bytes_dropped
    assert Faults(drop_rate=0.01, corrupt_rate=0.002, seed=seed).mangle(data) == out


def test_clean_line_is_untouched():
    data = bytes(range(256)) * 10
    assert Faults(seed=1).mangle(data) == data


def test_corruption_flips_exactly_one_bit():
    data = bytes(100_000)
    out = Faults(corrupt_rate=0.01, seed=3).mangle(data)
    bits = np.unpackbits(np.frombuffer(out, np.uint8)).reshape(-1, 8).sum(axis=1)
    assert set(bits.tolist()) <= {0, 1} and bits.sum() > 0


def test_control_commands():
    f = Faults()
    assert f.apply("silence 3") == "node 3 silenced" and f.silent == {3}
    f.apply("resume 3")
    assert f.silent == set()
    f.apply("drop 0.5")
    assert f.drop_rate == 0.5
    for bad in ("drop 2", "delay -1", "noise nan", "explode 1", "silence"):
        with pytest.raises(ValueError, match="fault command"):
            f.apply(bad)
