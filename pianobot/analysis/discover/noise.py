"""Noise level and systematic error of residuals: what part of a misfit is physics, what is noise.

The measurement noise is estimated from high-order differences of the residual along time: a
smooth systematic misfit (sampled at 120 Hz it changes slowly) is almost annihilated by a
4th-order difference, white noise is amplified by a known factor. The systematic error is then
√(RMS² − σ²), the part of the misfit that a better model could remove.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

# Var of the k-th difference of white noise is C(2k, k)·σ²; k = 4 kills cubic trends exactly.
_ORDER = 4
_BINOMIAL = np.array([1.0, -4.0, 6.0, -4.0, 1.0])
_GAIN = float(np.sqrt(np.sum(_BINOMIAL**2)))  # √70
_MAD_TO_SIGMA = 1.4826


def high_order_differences(residual: FloatArray) -> FloatArray:
    """4th differences over runs of finite samples only (a dropped frame breaks the run)."""
    r = np.asarray(residual, dtype=np.float64)
    if r.size <= _ORDER:
        return np.empty(0)
    d = np.convolve(r, _BINOMIAL, mode="valid")
    return d[np.isfinite(d)]


def noise_sigma(residuals: Sequence[FloatArray]) -> float:
    """Robust white-noise level (same unit as the residuals) from their 4th differences.

    The median absolute deviation ignores the few large differences at kinks (contact, keybed).
    Returns NaN when there are too few contiguous samples.
    """
    parts = [high_order_differences(r) for r in residuals]
    d = np.concatenate(parts) if parts else np.empty(0)
    if d.size < 8:
        return float("nan")
    mad = float(np.median(np.abs(d - np.median(d))))
    return _MAD_TO_SIGMA * mad / _GAIN


def rms(values: FloatArray) -> float:
    """Root mean square over finite values (NaN if none)."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    return float(np.sqrt(np.mean(v**2))) if v.size else float("nan")


def systematic_rms(values: FloatArray, sigma: float) -> float:
    """√(RMS² − σ²): the misfit left after removing the noise floor (0 when below it)."""
    r = rms(values)
    if not np.isfinite(r):
        return float("nan")
    s = sigma if np.isfinite(sigma) else 0.0
    return float(np.sqrt(max(r * r - s * s, 0.0)))


def lag1_autocorrelation(residual: FloatArray) -> float:
    """Lag-1 autocorrelation over consecutive finite pairs; ≈ 0 for white noise, → 1 for misfit."""
    r = np.asarray(residual, dtype=np.float64)
    if r.size < 3:
        return float("nan")
    a, b = r[:-1], r[1:]
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3:
        return float("nan")
    a, b = a[ok], b[ok]
    mean = float(np.mean(np.concatenate([a, b])))
    a, b = a - mean, b - mean
    denominator = float(np.sqrt(np.sum(a * a) * np.sum(b * b)))
    return float(np.sum(a * b) / denominator) if denominator > 0 else float("nan")


def quantisation_sigma(step: float = 1.0) -> float:
    """Standard deviation of rounding to integers of size `step` (MIDI velocities): step/√12."""
    return step / float(np.sqrt(12.0))
