"""The keystroke-event assignment pianobot used before issue 12, kept as the benchmark's baseline.

A dense dynamic programme over every (press, line) pair: cost and back-pointer arrays of
presses × lines, a step loop over up to MAX_SKIP silent lines, and pairwise merging of presses
whenever no assignment was feasible. Time O(m·n·MAX_SKIP), memory O(m·n) (20k lines: ~3 GB).
Same inputs as `pianobot.io.keystroke_assign` (press times and read lines, drains, predicted
cycle and down-move times), so both are timed on identical work. Do not use it for imports.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
SILENT_COST = 2.0
TIMING_REL_SD = 0.2
TIMING_ABS_SD_S = 0.3
MAX_SKIP = 12


def assign(t_s: FloatArray, first_read: npt.NDArray[np.int64], n_records: int, drains: list[bool],
           cycle_s: FloatArray, down_s: FloatArray) -> list[int]:  # fmt: skip
    """Line of each (possibly merged) press, as the old importer chose it."""
    t, first = list(t_s), list(first_read)
    while t:
        keys = _best(np.array(t), np.array(first), n_records, drains, cycle_s, down_s)
        if keys is not None:
            return keys
        if len(t) < 2:
            return first
        j = int(np.argmin(np.diff(t)))
        t[j : j + 2] = [t[j]]
        first[j : j + 2] = [min(first[j], first[j + 1])]
    return []


def _best(t: FloatArray, first: npt.NDArray[np.int64], n_records: int, drains: list[bool],
          cycle_motion: FloatArray, down_motion: FloatArray) -> list[int] | None:  # fmt: skip
    m = t.size
    last_drain, latest = [], -1
    for r, drained in enumerate(drains):
        last_drain.append(latest)
        if drained:
            latest = r
    lo = [last_drain[f] + 1 for f in first]
    hi = list(first)
    constant = _constant(t, lo, hi, cycle_motion, down_motion)
    cycle = cycle_motion + (constant if constant is not None else 0.0)
    start = np.concatenate([[0.0], np.cumsum(cycle)])
    k_all = np.arange(n_records)
    cost = np.full(n_records, math.inf)
    ok = (k_all >= lo[0]) & (k_all <= hi[0])
    cost[ok] = SILENT_COST * (k_all[ok] - lo[0])
    back = [np.full(n_records, -1, dtype=np.int64)]
    for i in range(1, m):
        new = np.full(n_records, math.inf)
        arg = np.full(n_records, -1, dtype=np.int64)
        gap = t[i] - t[i - 1]
        for skip in range(0, min(MAX_SKIP, n_records) + 1):
            step = skip + 1
            k = k_all[step:]
            prev = k - step
            total = cost[prev] + SILENT_COST * skip
            if constant is not None:
                expected = start[k] - start[prev] + down_motion[k] - down_motion[prev]
                z = (gap - expected) / (TIMING_REL_SD * np.abs(expected) + TIMING_ABS_SD_S)
                total = total + z * z
            better = total < new[step:]
            new[step:] = np.where(better, total, new[step:])
            arg[step:] = np.where(better, prev, arg[step:])
        allowed = (k_all >= lo[i]) & (k_all <= hi[i])
        new[~allowed] = math.inf
        cost = new
        back.append(arg)
    if not np.isfinite(cost).any():
        return None
    keys = [int(np.argmin(cost))]
    for i in range(m - 1, 0, -1):
        keys.append(int(back[i][keys[-1]]))
    keys.reverse()
    return keys


def _constant(t: FloatArray, lo: list[int], hi: list[int], cycle: FloatArray, down: FloatArray) -> float | None:
    keys: list[int] = []
    for i in range(t.size):
        k = lo[i] if not keys else max(lo[i], keys[-1] + 1)
        keys.append(min(k, hi[i]))
    residuals = [
        (t[i] - t[i - 1]) - (cycle[keys[i - 1]] + down[keys[i]] - down[keys[i - 1]])
        for i in range(1, t.size)
        if keys[i] - keys[i - 1] == 1
    ]
    return max(0.0, float(np.median(residuals))) if residuals else None
