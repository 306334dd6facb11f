"""Compiled scan of `commanded.midi_outcomes`: where each simulated key trace crosses the
piano's sensors and release depth (numba).

One pass per row instead of five boolean arrays of the whole trace group: the same indices as
`argmax` over the masks (0 where a row has none), so the interpolations that follow, in NumPy,
give the same numbers bit for bit. The module is one file on purpose: numba's disk cache
(cache=True) watches only the source file of a cached function.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]
BoolArray = npt.NDArray[np.bool_]


@njit(cache=True)
def key_crossings(
    x2: FloatArray, valid: BoolArray, upper: float, lower: float, release: float,
) -> tuple[FloatArray, IntArray, IntArray, BoolArray, IntArray, BoolArray]:  # pragma: no cover (compiled)
    """Per row of the valid samples of `x2`: the deepest point (−inf: no valid sample), the
    first sample at or past `upper`, the first at or past `lower` and whether there is one,
    and the first at or above `release` after that one (counted after sample 0 where the key
    never reached `lower`) and whether there is one. An index is 0 where there is none."""
    n, t = x2.shape
    top = np.full(n, -np.inf)
    k_up = np.zeros(n, dtype=np.intp)
    k_lo = np.zeros(n, dtype=np.intp)
    k_off = np.zeros(n, dtype=np.intp)
    sounded = np.zeros(n, dtype=np.bool_)
    released = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        deepest = -np.inf
        up = -1
        lo = -1
        for k in range(t):
            if not valid[i, k]:
                continue
            v = x2[i, k]
            if v > deepest:
                deepest = v
            if up < 0 and v >= upper:
                up = k
            if lo < 0 and v >= lower:
                lo = k
        top[i] = deepest
        k_up[i] = max(up, 0)
        k_lo[i] = max(lo, 0)
        sounded[i] = lo >= 0
        for k in range(k_lo[i] + 1, t):
            if valid[i, k] and x2[i, k] <= release:
                k_off[i] = k
                released[i] = True
                break
    return top, k_up, k_lo, sounded, k_off, released
