"""Compiled loops behind a simulated keystroke's observation (`world.World._observe`, `piano`).

Each replaces a chain of small NumPy calls over one keystroke's samples (a few thousand) by one
pass: at this size the calls' fixed cost, not the arithmetic, was most of the observation.
Every result is bit for bit what the NumPy code gave (the same IEEE operations in the same
order; compiled without fast-math, so nothing is fused or reordered): a keystroke observed by
this pianobot equals one observed by an older one, and a resumed run equals an uninterrupted one
(tests/physics/test_observe_kernel.py checks them against the NumPy forms).

The module stays one file on purpose: numba's disk cache (cache=True) only watches the source
file of the cached function.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

FloatArray = npt.NDArray[np.float64]


@njit(cache=True)
def interp(x: FloatArray, xp: FloatArray, fp: FloatArray) -> FloatArray:  # pragma: no cover (compiled)
    """`np.interp(x, xp, fp)` for increasing `xp` with at least two points, as NumPy computes
    it: the slope of the bracketing interval times the offset from its left end, plus the left
    value; a query on a sample point gives that sample; beyond the ends, the end values."""
    n = xp.size
    out = np.empty(x.size)
    j = 0
    for i in range(x.size):
        v = x[i]
        if math.isnan(v):
            out[i] = v
            continue
        if v < xp[0]:
            out[i] = fp[0]
            continue
        if v > xp[n - 1]:
            out[i] = fp[n - 1]
            continue
        if v < xp[j]:  # a query below the last one: search again from the start
            j = 0
        while j + 1 < n and xp[j + 1] <= v:
            j += 1
        if j == n - 1 or xp[j] == v:
            out[i] = fp[j]
            continue
        slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
        y = slope * (v - xp[j]) + fp[j]
        if math.isnan(y):  # as NumPy: try from the other end, then a flat interval's value
            y = slope * (v - xp[j + 1]) + fp[j + 1]
            if math.isnan(y) and fp[j] == fp[j + 1]:
                y = fp[j]
        out[i] = y
    return out


@njit(cache=True)
def crossing_times(t_s: FloatArray, x: FloatArray, level: float, downward: bool) -> FloatArray:  # pragma: no cover
    """The times `x` passes `level` (downward: from below to at or above it; else from above to
    at or below it), interpolated between the two samples around each passage."""
    count = 0
    for k in range(1, x.size):
        if (x[k - 1] < level and x[k] >= level) if downward else (x[k - 1] > level and x[k] <= level):
            count += 1
    out = np.empty(count)
    m = 0
    for k in range(1, x.size):
        if (x[k - 1] < level and x[k] >= level) if downward else (x[k - 1] > level and x[k] <= level):
            frac = (level - x[k - 1]) / (x[k] - x[k - 1])
            out[m] = t_s[k - 1] + frac * (t_s[k] - t_s[k - 1])
            m += 1
    return out


@njit(cache=True)
def settled(
    t_s: FloatArray, x1_m: FloatArray, x2_m: FloatArray, v2_mps: FloatArray, t_end_s: float,
    tol_m: float, lower_m: float,
) -> tuple[float, int, float, float]:  # pragma: no cover (compiled)
    """(rest time, samples kept, key speed at the lower sensor, deepest key position) of one
    keystroke's truth up to its own horizon.

    Rest time: motion start to the arm back up and the key within `tol_m` of rest for good, at
    most the horizon; the samples up to it are kept. The speed is interpolated where the key
    first passes `lower_m` downward among them (NaN if it never does); the depth is NaN if any
    kept sample is.
    """
    n = t_s.size
    last = 0.0
    for k in range(n - 1, -1, -1):
        if abs(x2_m[k]) > tol_m or abs(x1_m[k]) > tol_m:
            last = t_s[k]
            break
    duration = min(max(t_end_s, last + 1e-3), t_s[n - 1])
    edge = duration + 1e-9
    keep = 0
    while keep < n and t_s[keep] <= edge:
        keep += 1
    speed = math.nan
    for k in range(keep - 1):
        if x2_m[k] < lower_m and x2_m[k + 1] >= lower_m:
            f = (lower_m - x2_m[k]) / (x2_m[k + 1] - x2_m[k])
            speed = v2_mps[k] + f * (v2_mps[k + 1] - v2_mps[k])
            break
    deepest = -math.inf
    for k in range(keep):
        v = x2_m[k]
        if math.isnan(v):
            deepest = v
            break
        if v > deepest:
            deepest = v
    return duration, keep, speed, deepest


@njit(cache=True)
def last_beyond(x: FloatArray, level: float, absolute: bool) -> int:  # pragma: no cover (compiled)
    """The last index k where |x[k]| > level (`absolute`), else where x[k] >= level; -1 if none."""
    for k in range(x.size - 1, -1, -1):
        if (abs(x[k]) > level) if absolute else (x[k] >= level):
            return k
    return -1
