"""The one noise estimator of the grey-box fitter, and the statistics of what is left over.

Noise of a measured trace (or of a residual along a keystroke) is read from its second
differences: arm, fingertip and key move smoothly at the mocap rate over most samples (rest,
hold), so there the second difference is noise only, Var(Δ²e) = 6σ², and the median ignores the
few samples where the motion itself curves (accelerations, contact, ringing). Applied to the
residual of a fitted model, what the model explains is gone and differencing removes what is
left of any smooth model error, so it reads the noise alone.

MIDI outcomes have their own floors: integer velocities (rounding, σ = 1/√12) and the piano's
1 ms clock.

The systematic part of a misfit is √(RMS² − σ²): what a better model could remove. How many
independent samples a residual holds is its length over its integrated autocorrelation time.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

#: σ of rounding to integer MIDI velocities.
VELOCITY_QUANTUM_SIGMA = 1.0 / math.sqrt(12.0)
#: σ of the piano's 1 ms MIDI clock (rounding plus scan jitter, rounded up).
MIDI_TIME_SIGMA_S = 1e-3
_MAD_TO_SIGMA = 1.4826


def sigma_from_second_differences(d2: FloatArray) -> float:
    """White-noise σ from second differences Δ²x of smooth traces (NaNs ignored)."""
    d2 = np.asarray(d2, dtype=np.float64)
    d2 = d2[np.isfinite(d2)]
    if d2.size == 0:
        return 0.0
    return float(_MAD_TO_SIGMA * np.median(np.abs(d2)) / math.sqrt(6.0))


def noise_sigma_m(x: FloatArray) -> float:
    """Sample noise σ of smooth traces (rows of x, NaN breaks a run), from second differences."""
    return sigma_from_second_differences(np.diff(np.asarray(x, dtype=np.float64), n=2, axis=-1).ravel())


def pooled_noise_m(traces: Sequence[FloatArray]) -> float:
    """Noise σ of traces of different lengths: their second differences pooled."""
    d2 = [np.diff(np.asarray(x)[np.isfinite(x)], n=2) for x in traces]
    return sigma_from_second_differences(np.concatenate(d2)) if d2 else 0.0


def rms(values: FloatArray) -> float:
    """Root mean square over finite values (NaN if none)."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    return float(np.sqrt(np.mean(v**2))) if v.size else math.nan


def systematic_rms(values: FloatArray, sigma: float) -> float:
    """√(RMS² − σ²): the misfit left after removing the noise floor (0 when below it)."""
    r = rms(values)
    if not math.isfinite(r):
        return math.nan
    s = sigma if math.isfinite(sigma) else 0.0
    return float(math.sqrt(max(r * r - s * s, 0.0)))


def lag1_autocorrelation(residual: FloatArray) -> float:
    """Lag-1 autocorrelation over consecutive finite pairs; ≈ 0 for white noise, → 1 for misfit."""
    r = np.asarray(residual, dtype=np.float64)
    if r.size < 3:
        return math.nan
    a, b = r[:-1], r[1:]
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3:
        return math.nan
    a, b = a[ok], b[ok]
    mean = float(np.mean(np.concatenate([a, b])))
    a, b = a - mean, b - mean
    denominator = float(np.sqrt(np.sum(a * a) * np.sum(b * b)))
    return float(np.sum(a * b) / denominator) if denominator > 0 else math.nan


def autocorrelation_time(series: FloatArray, c: float = 5.0) -> float:
    """Integrated autocorrelation time τ of residual series (rows, NaN where not sampled).

    τ(W) = 1 + 2 Σ_{l≤W} ρ(l) is accumulated until W ≥ c·τ(W) (Sokal's automatic window), with
    ρ pooled over the rows; a residual of n samples then holds about n/τ independent ones. 1 for
    white residuals; a smooth systematic misfit along a keystroke gives tens.
    """
    x = np.atleast_2d(np.asarray(series, dtype=np.float64))
    ok = np.isfinite(x)
    x = np.where(ok, x - np.nanmean(np.where(ok, x, np.nan)) if ok.any() else 0.0, 0.0)
    var = float(np.sum(x * x))
    T = x.shape[1]
    if var <= 0 or T < 3:
        return 1.0
    tau = 1.0
    for ell in range(1, T // 2):
        pairs = ok[:, ell:] & ok[:, :-ell]
        n_pairs = int(pairs.sum())
        if n_pairs == 0:
            break
        rho = float(np.sum(x[:, ell:] * x[:, :-ell])) / var * ok.sum() / n_pairs
        tau += 2.0 * rho
        if ell >= c * max(tau, 1.0):
            break
    return float(min(max(tau, 1.0), T))
