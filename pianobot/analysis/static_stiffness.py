"""Static finger stiffness from force-sensor presses (the study's method) and its vacuum law.

The finger is pressed onto a force sensor by a fixed compression at each vacuum level; the
stiffness is the peak force of a press divided by that compression (the study used 13.9 mm for
every level), averaged over the presses of a level; then k1(p) = a + b·|p| is fitted by least
squares with a 95 % interval from the fit's covariance.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pianobot.errors import InputError

FloatArray = npt.NDArray[np.float64]
STUDY_COMPRESSION_M = 0.0139
Z95 = 1.959963984540054


def burst_peaks_n(force_n: npt.ArrayLike, *, threshold_fraction: float = 0.3, min_samples: int = 5) -> FloatArray:
    """Peak force of each press: contiguous runs above a fraction of the log's maximum.

    Runs separated by fewer than `min_samples` quiet samples are one press (the sensor
    chatters on release); runs shorter than `min_samples` are noise.
    """
    f = np.asarray(force_n, dtype=np.float64)
    f = f[np.isfinite(f)]
    if f.size == 0:
        return np.zeros(0)
    base = float(np.median(f))
    level = base + threshold_fraction * (float(f.max()) - base)
    on = np.r_[False, f > level, False]
    edges = np.flatnonzero(np.diff(on.astype(np.int8)))
    runs = [[int(a), int(b)] for a, b in zip(edges[::2], edges[1::2], strict=True)]
    merged: list[list[int]] = []
    for run in runs:
        if merged and run[0] - merged[-1][1] < min_samples:
            merged[-1][1] = run[1]
        else:
            merged.append(run)
    peaks = np.array([f[a:b].max() for a, b in merged if b - a >= min_samples], dtype=np.float64)
    # A real press reaches most of the compression force; half-height bursts are re-touches.
    return peaks[peaks >= base + 0.5 * (float(peaks.max(initial=base)) - base)] if peaks.size else peaks


@dataclass(frozen=True)
class StaticStiffness:
    """Per-level stiffness and the fitted law k1 = a + b·|p|."""

    levels_kpa: FloatArray
    k1_npm: FloatArray
    n_presses: tuple[int, ...]
    k1_a_npm: float
    k1_b_npm_per_kpa: float
    ci_a: tuple[float, float]
    ci_b: tuple[float, float]
    compression_m: float


def static_stiffness(peaks_by_level: Mapping[float, Sequence[float]], *, compression_m: float = STUDY_COMPRESSION_M) -> StaticStiffness:
    """Stiffness per vacuum level (mean peak / compression) and the linear law through them."""
    if not compression_m > 0:
        raise InputError(f"compression should be > 0 m, got {compression_m}", "--compression-m")
    levels = sorted(peaks_by_level, key=abs)
    usable = [p for p in levels if len(peaks_by_level[p]) > 0]
    if len(usable) < 2:
        raise InputError(f"need presses at two or more vacuum levels, got {len(usable)}", "--force-log")
    p = np.abs(np.array(usable, dtype=np.float64))
    k = np.array([float(np.mean(peaks_by_level[v])) / compression_m for v in usable])
    X = np.column_stack([np.ones_like(p), p])
    coef, *_ = np.linalg.lstsq(X, k, rcond=None)
    resid = k - X @ coef
    dof = max(p.size - 2, 1)
    cov = float(resid @ resid) / dof * np.linalg.inv(X.T @ X)
    sa, sb = math.sqrt(cov[0, 0]), math.sqrt(cov[1, 1])
    a, b = float(coef[0]), float(coef[1])
    return StaticStiffness(
        levels_kpa=-p, k1_npm=k, n_presses=tuple(len(peaks_by_level[v]) for v in usable),
        k1_a_npm=a, k1_b_npm_per_kpa=b, ci_a=(a - Z95 * sa, a + Z95 * sa),
        ci_b=(b - Z95 * sb, b + Z95 * sb), compression_m=compression_m,
    )
