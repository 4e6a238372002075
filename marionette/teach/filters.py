"""Syntactic and semantic filters of the teach-in trajectory (Hoffmann 1996, section 6).

* Syntactic: :func:`complement_missing_led` - one missing LED of a set is rebuilt from
  the other three (the LEDs form a square, so ``L1 + L3 = L2 + L4``, LED order as in
  :mod:`marionette.teach.rucksack`); sets with two or more missing LEDs are marked.
* Semantic:
  - :func:`bridge_gaps` - linear bridging of missing samples (NaN);
  - :func:`design_lowpass` / :func:`fir_filter` - a 21-tap linear-phase FIR low-pass
    designed by the window method (default cutoff 2.0 Hz at 12.5 Hz sample rate,
    Hamming window), applied without delay (the (N-1)/2-sample group delay of the
    symmetric filter is removed by centring);
  - :class:`SoftLimit` - smooth monotone compression of the dancer's working area
    (4 m x 4 m) into the marionette's (1.5 m x 1.5 m), per horizontal axis;
  - :func:`resample` - from the 12.5 Hz set rate to the 20 ms tick (50 Hz).

The pragmatic (parabolic) filter is not part of this module.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from marionette.errors import ArgumentError

DEFAULT_NUMTAPS = 21          # FIR length [taps]
DEFAULT_SAMPLE_RATE = 12.5    # rate of LED sets [Hz]
DEFAULT_CUTOFF = 2.0          # -6 dB point of the low-pass [Hz]
TICK = 0.020                  # show tick [s] (50 Hz)


# ----------------------------------------------------------------------------------
# Syntactic filter
# ----------------------------------------------------------------------------------
def complement_missing_led(points):
    """Complete sets with exactly one missing LED; mark sets with more.

    ``points`` (K, 4, 3) [m], NaN rows for missing LEDs (order LED1..LED4 around the
    square).  A missing LED ``j`` is ``L[j-1] + L[j+1] - L[j+2]`` (indices mod 4:
    its two neighbours minus the diagonal opposite), exact for a rigid square.

    Returns ``(filled (K, 4, 3), n_missing (K,) int)``; sets with ``n_missing >= 2``
    are entirely NaN in ``filled``.
    """
    X = np.array(points, dtype=float, copy=True)
    if X.ndim != 3 or X.shape[1:] != (4, 3):
        raise ArgumentError(f"points must have shape (K, 4, 3) [m], got {X.shape}")
    missing = ~np.all(np.isfinite(X), axis=2)          # (K, 4)
    n_missing = missing.sum(axis=1)
    X[missing] = np.nan
    for j in range(4):
        sel = missing[:, j] & (n_missing == 1)
        X[sel, j] = X[sel, (j - 1) % 4] + X[sel, (j + 1) % 4] - X[sel, (j + 2) % 4]
    X[n_missing >= 2] = np.nan
    return X, n_missing


# ----------------------------------------------------------------------------------
# Gaps and angles
# ----------------------------------------------------------------------------------
def unwrap_angle(angle):
    """Unwrap an angle sequence [rad] (K,) ignoring NaN samples (they stay NaN)."""
    a = np.array(angle, dtype=float, copy=True)
    ok = np.isfinite(a)
    a[ok] = np.unwrap(a[ok])
    return a


def bridge_gaps(t, y, max_gap: float | None = None):
    """Linear bridging of NaN samples.

    ``t`` (K,) increasing [s]; ``y`` (K,) or (K, m) in any unit.  Interior gaps are
    bridged by a straight line between the valid neighbours; leading and trailing gaps
    hold the first/last valid value.  With ``max_gap`` [s], a gap whose valid
    neighbours are further apart raises ``ValueError`` naming its times.

    Returns ``(bridged, was_missing)`` with the same shapes as ``y``.
    """
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    one_d = y.ndim == 1
    Y = y[:, None] if one_d else y
    if Y.shape[0] != t.size:
        raise ArgumentError(f"t has {t.size} samples but y has {Y.shape[0]}")
    if np.any(np.diff(t) <= 0):
        raise ArgumentError("t must be strictly increasing")
    out = Y.copy()
    missing = ~np.isfinite(Y)
    for col in range(Y.shape[1]):
        ok = ~missing[:, col]
        if not np.any(ok):
            raise ArgumentError(f"column {col} has no valid sample to bridge from")
        tv = t[ok]
        if max_gap is not None and tv.size > 1:
            gaps = np.diff(tv)
            k = np.nonzero(gaps > max_gap)[0]
            if k.size:
                raise ArgumentError(
                    f"gap from t={tv[k[0]]:.3f} s to t={tv[k[0] + 1]:.3f} s "
                    f"({gaps[k[0]]:.3f} s) exceeds max_gap={max_gap} s"
                )
        out[:, col] = np.interp(t, tv, Y[ok, col])
    if one_d:
        return out[:, 0], missing[:, 0]
    return out, missing


# ----------------------------------------------------------------------------------
# FIR low-pass (window method)
# ----------------------------------------------------------------------------------
def window(name: str, n: int) -> np.ndarray:
    """Symmetric window of length ``n``: 'hamming', 'hann', 'blackman' or 'rectangular'."""
    k = np.arange(n)
    x = 2.0 * np.pi * k / (n - 1) if n > 1 else np.zeros(1)
    if name == "hamming":
        return 0.54 - 0.46 * np.cos(x)
    if name == "hann":
        return 0.5 - 0.5 * np.cos(x)
    if name == "blackman":
        return 0.42 - 0.5 * np.cos(x) + 0.08 * np.cos(2.0 * x)
    if name == "rectangular":
        return np.ones(n)
    raise ArgumentError(f"unknown window {name!r}")


def design_lowpass(
    cutoff_hz: float = DEFAULT_CUTOFF,
    sample_rate_hz: float = DEFAULT_SAMPLE_RATE,
    numtaps: int = DEFAULT_NUMTAPS,
    window_name: str = "hamming",
) -> np.ndarray:
    """Linear-phase FIR low-pass by the window method.

    Ideal low-pass impulse response ``h[n] = 2 fc sinc(2 fc (n - M))`` with
    ``fc = cutoff/sample_rate`` [cycles/sample] and ``M = (numtaps - 1)/2``, multiplied
    by the window and normalised to unit DC gain (sum of taps = 1).  ``numtaps`` must
    be odd (type I filter, symmetric taps, group delay M samples).  With the defaults
    (21 taps, Hamming, 2.0 Hz at 12.5 Hz) the gain is 0.5 (-6 dB) at the cutoff, within
    0.5 % of 1 up to 1.0 Hz and below -50 dB from 3.5 Hz to Nyquist (6.25 Hz); see
    the tests.
    """
    if numtaps < 3 or numtaps % 2 == 0:
        raise ArgumentError(f"numtaps={numtaps} must be odd and >= 3")
    nyquist = 0.5 * sample_rate_hz
    if not 0.0 < cutoff_hz < nyquist:
        raise ArgumentError(f"cutoff {cutoff_hz} Hz must lie in (0, {nyquist}) Hz (Nyquist)")
    fc = cutoff_hz / sample_rate_hz
    m = np.arange(numtaps) - (numtaps - 1) / 2.0
    h = 2.0 * fc * np.sinc(2.0 * fc * m) * window(window_name, numtaps)
    return h / h.sum()


def frequency_response(taps, freq_hz, sample_rate_hz: float = DEFAULT_SAMPLE_RATE) -> np.ndarray:
    """Complex response ``H(f) = sum_n h[n] exp(-2 pi i f n / fs)`` at ``freq_hz`` [Hz]."""
    taps = np.asarray(taps, float)
    f = np.asarray(freq_hz, float)
    n = np.arange(taps.size)
    return np.exp(-2j * np.pi * np.multiply.outer(f, n) / sample_rate_hz) @ taps


def fir_filter(y, taps) -> np.ndarray:
    """Apply a symmetric FIR without delay along axis 0.

    ``y`` (K,) or (K, m) without NaN.  The ends are padded with the first/last value
    (so a constant stays constant), the output sample k is ``sum_n h[n] y[k + M - n]``.
    """
    taps = np.asarray(taps, float)
    y = np.asarray(y, float)
    if not np.all(np.isfinite(y)):
        raise ArgumentError("fir_filter: input contains NaN/inf; bridge gaps first")
    if taps.size % 2 == 0 or not np.allclose(taps, taps[::-1]):
        raise ArgumentError("fir_filter needs symmetric taps of odd length (linear phase)")
    M = taps.size // 2
    one_d = y.ndim == 1
    Y = y[:, None] if one_d else y
    if Y.shape[0] == 0:
        return y.copy()
    padded = np.concatenate([np.repeat(Y[:1], M, axis=0), Y, np.repeat(Y[-1:], M, axis=0)])
    out = np.empty_like(Y)
    for col in range(Y.shape[1]):
        out[:, col] = np.convolve(padded[:, col], taps, mode="valid")
    return out[:, 0] if one_d else out


# ----------------------------------------------------------------------------------
# Working-area compression
# ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class SoftLimit:
    """Smooth monotone compression ``x [m] -> y [m]`` of one horizontal axis.

    ``z = gain (x - in_center)``; inside ``|z| <= knee`` the map is linear,
    ``y = out_center + z``; outside it bends with a tanh,
    ``y = out_center + sign(z) (knee + (limit - knee) tanh((|z| - knee)/(limit - knee)))``,
    so the slope and curvature are continuous at the knee (C2), the map is strictly
    increasing, and ``|y - out_center| < limit`` for every input (``<=`` in floating
    point, where tanh saturates to 1 far outside): the marionette never leaves its area
    however far the dancer walks.
    """

    in_center: float    # centre of the dancer's area [m]
    out_center: float   # centre of the marionette's area [m]
    gain: float         # linear scale near the centre [m/m]
    knee: float         # half-width of the linear zone, output side [m]
    limit: float        # output half-range, approached asymptotically [m]

    def __post_init__(self) -> None:
        if not (self.gain > 0 and 0 <= self.knee < self.limit):
            raise ArgumentError(
                f"SoftLimit needs gain > 0 and 0 <= knee < limit, got gain={self.gain}, "
                f"knee={self.knee}, limit={self.limit}"
            )

    def __call__(self, x):
        z = self.gain * (np.asarray(x, float) - self.in_center)
        a = np.abs(z)
        span = self.limit - self.knee
        bent = self.knee + span * np.tanh((a - self.knee) / span)
        return self.out_center + np.where(a <= self.knee, z, np.sign(z) * bent)

    def inverse(self, y):
        """Inverse map for ``|y - out_center| < limit`` [m]."""
        d = np.asarray(y, float) - self.out_center
        a = np.abs(d)
        span = self.limit - self.knee
        if np.any(a >= self.limit):
            raise ArgumentError(f"inverse defined only for |y - out_center| < {self.limit} m")
        bent = self.knee + span * np.arctanh(np.clip((a - self.knee) / span, 0.0, 1.0 - 1e-16))
        z = np.where(a <= self.knee, d, np.sign(d) * bent)
        return self.in_center + z / self.gain


def soft_limit_for_areas(
    in_center: float,
    in_half: float,
    out_center: float,
    out_half: float,
    knee_fraction: float = 0.6,
    edge_fraction: float = 0.95,
) -> SoftLimit:
    """SoftLimit mapping the dancer's edge ``in_center +- in_half`` [m] to
    ``out_center +- edge_fraction * out_half`` [m], linear up to ``knee_fraction *
    out_half`` and bounded by ``out_half``.  E.g. 4 m -> 1.5 m: in_half 2, out_half 0.75."""
    if not (0 <= knee_fraction < edge_fraction < 1):
        raise ArgumentError("need 0 <= knee_fraction < edge_fraction < 1")
    knee = knee_fraction * out_half
    span = out_half - knee
    z_edge = knee + span * math.atanh((edge_fraction * out_half - knee) / span)
    return SoftLimit(in_center, out_center, z_edge / in_half, knee, out_half)


# ----------------------------------------------------------------------------------
# Resampling to the 20 ms tick
# ----------------------------------------------------------------------------------
def resample(t, y, dt: float = TICK, t_start: float | None = None, t_end: float | None = None,
             method: str = "cubic"):
    """Resample ``y`` (K,) or (K, m) given at increasing times ``t`` [s] onto a grid of
    step ``dt`` [s] (default the 20 ms tick).

    The grid is ``t_start + k dt`` within ``[t[0], t[-1]]``; ``t_start`` defaults to the
    first multiple of ``dt`` at or after ``t[0]``.  ``method``: 'linear', or 'cubic' =
    cubic Hermite with Catmull-Rom tangents ``(y[i+1] - y[i-1]) / (t[i+1] - t[i-1])``
    (one-sided at the ends): C1, exact for straight lines, no overshoot beyond a
    Catmull-Rom's.  Returns ``(t_out, y_out)``.
    """
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    one_d = y.ndim == 1
    Y = y[:, None] if one_d else y
    if t.ndim != 1 or Y.shape[0] != t.size or t.size < 2:
        raise ArgumentError("resample needs t (K,), y (K, ...) with K >= 2 samples")
    if np.any(np.diff(t) <= 0):
        raise ArgumentError("t must be strictly increasing")
    if not np.all(np.isfinite(Y)):
        raise ArgumentError("resample: input contains NaN/inf; bridge gaps first")
    if not dt > 0:
        raise ArgumentError(f"dt={dt} s must be > 0")
    if t_start is None:
        t_start = math.ceil(t[0] / dt - 1e-9) * dt
    if t_end is None:
        t_end = t[-1]
    n = int(math.floor((t_end - t_start) / dt + 1e-9)) + 1
    t_out = t_start + dt * np.arange(max(n, 0))
    t_out = t_out[(t_out >= t[0] - 1e-12) & (t_out <= t[-1] + 1e-12)]
    tq = np.clip(t_out, t[0], t[-1])
    i = np.clip(np.searchsorted(t, tq, side="right") - 1, 0, t.size - 2)
    h = t[i + 1] - t[i]
    s = ((tq - t[i]) / h)[:, None]                      # position in the interval [1]
    y0, y1 = Y[i], Y[i + 1]
    if method == "linear":
        out = (1.0 - s) * y0 + s * y1
    elif method == "cubic":
        m = np.empty_like(Y)                            # tangents [unit/s]
        m[1:-1] = (Y[2:] - Y[:-2]) / (t[2:] - t[:-2])[:, None]
        m[0] = (Y[1] - Y[0]) / (t[1] - t[0])
        m[-1] = (Y[-1] - Y[-2]) / (t[-1] - t[-2])
        s2, s3 = s * s, s * s * s
        out = ((2 * s3 - 3 * s2 + 1) * y0 + (s3 - 2 * s2 + s) * h[:, None] * m[i]
               + (-2 * s3 + 3 * s2) * y1 + (s3 - s2) * h[:, None] * m[i + 1])
    else:
        raise ArgumentError(f"unknown resampling method {method!r}; use 'linear' or 'cubic'")
    return t_out, (out[:, 0] if one_d else out)
