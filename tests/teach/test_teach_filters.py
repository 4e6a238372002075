"""Syntactic and semantic filters (section 6)."""

import numpy as np
import pytest

from marionette.teach.filters import (
    SoftLimit,
    bridge_gaps,
    complement_missing_led,
    design_lowpass,
    fir_filter,
    frequency_response,
    resample,
    soft_limit_for_areas,
    unwrap_angle,
    window,
)
from marionette.teach.rucksack import led_positions

SEED = 808


def test_complement_one_missing_led_is_exact_on_noise_free_data():
    rng = np.random.default_rng(SEED)
    n = 400
    pose = np.c_[rng.uniform(-2, 2, (n, 2)), rng.uniform(1, 1.6, n),
                 rng.uniform(-0.3, 0.3, (n, 2)), rng.uniform(-np.pi, np.pi, n)]
    X = led_positions(pose, 0.2)
    holed = X.copy()
    which = rng.integers(0, 4, n)
    holed[np.arange(n), which] = np.nan
    filled, n_missing = complement_missing_led(holed)
    assert np.all(n_missing == 1)
    np.testing.assert_allclose(filled, X, atol=1e-12)


def test_two_or_more_missing_are_marked():
    X = led_positions(np.array([[0, 0, 1.3, 0, 0, 0.5]] * 5), 0.2)
    X[1, 0] = np.nan
    X[2, [0, 2]] = np.nan
    X[3, [0, 1, 3]] = np.nan
    X[4] = np.nan
    filled, n_missing = complement_missing_led(X)
    assert n_missing.tolist() == [0, 1, 2, 3, 4]
    assert np.all(np.isfinite(filled[:2])) and np.all(np.isnan(filled[2:]))
    # a partially NaN LED row counts as missing
    Y = led_positions(np.array([[0, 0, 1.3, 0, 0, 0.5]]), 0.2)
    Y[0, 3, 1] = np.nan
    assert complement_missing_led(Y)[1][0] == 1


def test_bridging_is_linear_and_holds_ends():
    rng = np.random.default_rng(SEED + 1)
    for _ in range(20):
        t = np.cumsum(rng.uniform(0.05, 0.1, 60))
        slope, offset = rng.normal(size=2)
        y = offset + slope * t
        holed = y.copy()
        holed[rng.choice(np.arange(3, 57), 15, replace=False)] = np.nan
        holed[:2] = np.nan
        holed[-1] = np.nan
        out, missing = bridge_gaps(t, holed)
        np.testing.assert_allclose(out[2:-1], y[2:-1], atol=1e-12)
        assert out[0] == out[1] == y[2] and out[-1] == y[-2]
        assert np.array_equal(missing, np.isnan(holed))


def test_bridging_multi_column_and_max_gap():
    t = np.arange(10) * 0.08
    y = np.c_[t, 2 * t]
    y[3:6, 0] = np.nan
    out, _ = bridge_gaps(t, y)
    np.testing.assert_allclose(out, np.c_[t, 2 * t], atol=1e-12)
    with pytest.raises(ValueError, match=r"gap from t=0.160 s to t=0.480 s"):
        bridge_gaps(t, y, max_gap=0.2)
    with pytest.raises(ValueError, match="no valid sample"):
        bridge_gaps(t, np.full(10, np.nan))


def test_unwrap_angle_skips_nan():
    psi = np.angle(np.exp(1j * np.linspace(0, 6 * np.pi, 100)))
    psi[[10, 50, 51]] = np.nan
    out = unwrap_angle(psi)
    ok = np.isfinite(out)
    np.testing.assert_allclose(out[ok], np.linspace(0, 6 * np.pi, 100)[ok], atol=1e-12)
    assert np.all(np.isnan(out[[10, 50, 51]]))


def test_fir_design_properties():
    """21 taps, cutoff 2.0 Hz at 12.5 Hz: unit DC gain, symmetric taps (linear phase,
    group delay 10 samples), |H| = 0.5 at the cutoff, |H - 1| <= 0.005 up to 1.0 Hz,
    |H| <= -50 dB from 3.5 Hz to Nyquist."""
    h = design_lowpass(2.0, 12.5, 21)
    assert h.size == 21
    assert h.sum() == pytest.approx(1.0, abs=1e-14)
    np.testing.assert_allclose(h, h[::-1], atol=0)
    f = np.linspace(0, 6.25, 2001)
    H = frequency_response(h, f, 12.5)
    # linear phase: H(f) exp(+i 2 pi f M / fs) is real
    real = H * np.exp(2j * np.pi * f * 10 / 12.5)
    assert np.max(np.abs(real.imag)) < 1e-12
    mag = np.abs(H)
    assert mag[0] == pytest.approx(1.0)
    assert abs(mag[f <= 1.0] - 1).max() <= 0.005
    assert np.abs(frequency_response(h, 2.0, 12.5)) == pytest.approx(0.5, abs=0.01)
    assert 20 * np.log10(mag[f >= 3.5].max()) <= -50.0


@pytest.mark.parametrize("win", ["hamming", "hann", "blackman", "rectangular"])
def test_fir_design_other_windows_and_rates(win):
    rng = np.random.default_rng(SEED + 2)
    for _ in range(5):
        fs = rng.uniform(10, 100)
        fc = rng.uniform(0.1, 0.35) * fs
        h = design_lowpass(fc, fs, 21, win)
        assert h.sum() == pytest.approx(1.0)
        np.testing.assert_allclose(h, h[::-1])
        assert np.abs(frequency_response(h, fs / 2, fs)) < 0.3
    assert window(win, 21)[10] == pytest.approx(1.0)


def test_fir_design_rejects_bad_arguments():
    with pytest.raises(ValueError, match="odd"):
        design_lowpass(2.0, 12.5, 20)
    with pytest.raises(ValueError, match="Nyquist"):
        design_lowpass(7.0, 12.5)
    with pytest.raises(ValueError, match="unknown window"):
        design_lowpass(2.0, 12.5, 21, "kaiser")


def test_fir_filter_has_no_delay_and_stated_attenuation():
    h = design_lowpass()
    t = np.arange(500) / 12.5
    mid = slice(30, -30)
    # constant stays constant, also at the ends
    np.testing.assert_allclose(fir_filter(np.full(500, 3.7), h), 3.7, rtol=1e-14)
    # 0.5 Hz passes without delay or loss
    slow = np.sin(2 * np.pi * 0.5 * t + 0.3)
    np.testing.assert_allclose(fir_filter(slow, h)[mid], slow[mid], atol=0.005)
    # 4.5 Hz is attenuated by >= 50 dB
    fast = np.sin(2 * np.pi * 4.5 * t)
    assert np.max(np.abs(fir_filter(fast, h)[mid])) < 10 ** (-50 / 20)
    # columns are filtered independently
    both = fir_filter(np.c_[slow, fast], h)
    np.testing.assert_allclose(both[:, 0], fir_filter(slow, h))
    with pytest.raises(ValueError, match="NaN"):
        fir_filter(np.array([1.0, np.nan, 2.0]), h)


def test_soft_limit_shape():
    """4 m x 4 m dancer area (half 2 m) into 1.5 m x 1.5 m (half 0.75 m)."""
    sl = soft_limit_for_areas(0.0, 2.0, 0.1, 0.75)
    x = np.linspace(-20, 20, 40001)
    y = sl(x)
    near = np.abs(x) <= 6.0
    assert np.all(np.diff(y[near]) > 0)                        # strictly increasing
    assert np.all(np.diff(y) >= 0)                             # (tanh saturates in floats)
    assert np.all(np.abs(y - 0.1) <= 0.75 + 1e-12)             # never leaves the area
    assert np.all(np.abs(y[near] - 0.1) < 0.75)
    assert sl(2.0) == pytest.approx(0.1 + 0.95 * 0.75)         # the dancer's edge
    assert sl(-2.0) == pytest.approx(0.1 - 0.95 * 0.75)
    inner = np.abs(x) < sl.knee / sl.gain
    np.testing.assert_allclose(y[inner], 0.1 + sl.gain * x[inner], atol=1e-15)   # linear core
    # slope continuous at the knee (C1): one-sided difference quotients agree
    xk, h = sl.knee / sl.gain, 1e-6
    left = (sl(xk) - sl(xk - h)) / h
    right = (sl(xk + h) - sl(xk)) / h
    assert left == pytest.approx(right, rel=1e-4)
    np.testing.assert_allclose(sl.inverse(y[np.abs(x) < 6]), x[np.abs(x) < 6], atol=1e-9)


def test_soft_limit_random_monotone_and_bounded():
    rng = np.random.default_rng(SEED + 3)
    for _ in range(50):
        limit = rng.uniform(0.1, 2.0)
        sl = SoftLimit(rng.normal(), rng.normal(), rng.uniform(0.1, 3.0), rng.uniform(0, 0.99) * limit, limit)
        x = np.sort(rng.normal(sl.in_center, 5.0, 2000))
        y = sl(x)
        assert np.all(np.diff(y) >= 0) and np.all(np.abs(y - sl.out_center) <= limit + 1e-12)
    with pytest.raises(ValueError, match="knee < limit"):
        SoftLimit(0, 0, 1.0, 1.0, 1.0)


def test_resample_to_tick():
    rng = np.random.default_rng(SEED + 4)
    t = 0.013 + 0.08 * np.arange(200)            # 12.5 Hz set times, arbitrary phase
    for method in ("linear", "cubic"):
        line = 0.4 - 1.3 * t
        to, yo = resample(t, line, method=method)
        np.testing.assert_allclose(np.diff(to), 0.02, atol=1e-12)
        assert to[0] == pytest.approx(0.02) and to[-1] <= t[-1]
        np.testing.assert_allclose(np.round(to / 0.02) * 0.02, to, atol=1e-12)
        np.testing.assert_allclose(yo, 0.4 - 1.3 * to, atol=1e-12)
    # a smooth motion (<= 0.4 Hz, in the passband) is reproduced within 0.3 % by the cubic
    for _ in range(10):
        f, p = rng.uniform(0.05, 0.4), rng.uniform(0, 2 * np.pi)
        to, yo = resample(t, np.sin(2 * np.pi * f * t + p))
        assert np.max(np.abs(yo - np.sin(2 * np.pi * f * to + p))) < 0.003
        _, yl = resample(t, np.sin(2 * np.pi * f * t + p), method="linear")
        assert np.max(np.abs(yl - np.sin(2 * np.pi * f * to + p))) < 0.02
    with pytest.raises(ValueError, match="NaN"):
        resample(t[:3], np.array([0.0, np.nan, 1.0]))
    with pytest.raises(ValueError, match="unknown resampling method"):
        resample(t, t, method="sinc")
