"""Compiled dynamic programme of `keystroke_assign` (numba; the costs are documented there).

Each press i may sit on lines lo[i]..hi[i] (its structural *band*); the candidates actually
scored are the part of it the previous press's surviving candidates allow (`_window`), stored
flat, press i's at offset off[i]. The forward pass keeps, per candidate line, the cost of the best assignment of
presses 0..i that puts press i there; the backward pass the cost of the best continuation; their
sum is the best total cost with press i on that line (its max-marginal). Time is
O(Σ band_i·band_{i-1}), memory O(Σ band_i): a press the structure pins to one line costs O(1).

The module is one file on purpose: numba's disk cache (cache=True) watches only the source file
of a cached function.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

# Costs are in squared standard deviations (a negative log-likelihood, up to constants).
BACKLOG_COST = 3.0  # prior cost of each line of backlog a press opens: ties keep the log as written
NOTE_COST = 40.0  # a press whose note differs from its line's key
SIGMA_ABS_S = 0.2  # timing spread of any gap: MIDI latency, scheduling, the read and the print
SIGMA_REL = 0.05  # relative spread of each predicted cycle: moveL blending, controller timing
SIGMA_REL_UNKNOWN = 0.3  # the same for a line whose motion the log does not give
PAUSE_Z = 3.0  # beyond this many SDs a too-long gap is a pause: it costs only
PAUSE_TAIL = 1.0  # ... PAUSE_TAIL·ln(z / PAUSE_Z) more, so 20 s and 25 s pauses cost alike
MAX_SILENT_RUN = 24  # lines of backlog one step may give back (silent keystrokes in a backlog)
BEAM = 60.0  # candidates costlier than their press's best by this much are not extended


@njit(cache=True)
def _pair(
    i: int,
    kp: int,
    k: int,
    o: float,
    scale: float,
    t: FloatArray,
    has_on: npt.NDArray[np.bool_],
    c1: FloatArray,
    c2: FloatArray,
    unk: FloatArray,
    early: FloatArray,
    late: FloatArray,
    motion: FloatArray,
) -> float:
    """Timing cost of press i-1 on line kp and press i on line k."""
    n = k - kp
    if n <= 0:
        return math.inf
    d1 = c1[k] - c1[kp]
    span = d1 + n * o
    late_i = late[k] if has_on[i] else motion[k] + o  # a lone note-off: any time in the cycle
    late_p = late[kp] if has_on[i - 1] else motion[kp] + o
    low = span + early[k] - late_p
    high = span + late_i - early[kp]
    var = (
        SIGMA_ABS_S**2
        + SIGMA_REL**2 * ((c2[k] - c2[kp]) + 2.0 * o * d1 + n * o * o)
        + (SIGMA_REL_UNKNOWN**2 - SIGMA_REL**2) * (unk[k] - unk[kp]) * o * o
    )
    sd = math.sqrt(max(var, SIGMA_ABS_S**2)) * scale
    dt = t[i] - t[i - 1]
    if dt < low:
        z = (dt - low) / sd
    elif dt > high:
        z = (dt - high) / sd
    else:
        return 0.0
    if z > PAUSE_Z:
        return float(PAUSE_Z * PAUSE_Z + PAUSE_TAIL * math.log(z / PAUSE_Z))
    return float(z * z)


@njit(cache=True)
def _node(
    i: int, k: int, m: int, note: IntArray, line_note: IntArray, silent_cost: float, last_drain: int
) -> float:
    """Note mismatch, and for the last press the cost of the silent lines its position implies."""
    cost = 0.0
    if note[i] >= 0 and line_note[k] >= 0 and line_note[k] != note[i]:
        cost += NOTE_COST
    if i == m - 1:
        cost += silent_cost * max(k, last_drain)
    return cost


@njit(cache=True)
def _backlog(i: int, kp: int, k: int, r: IntArray) -> float:
    grow = (r[i] - k) - (r[i - 1] - kp)
    return BACKLOG_COST * grow if grow > 0 else 0.0


@njit(cache=True)
def _window(
    i: int, lo: IntArray, hi: IntArray, r: IntArray, prev_first: int, prev_last: int
) -> tuple[int, int]:
    """Candidate lines of press i: its structural band, cut to what the previous press's surviving
    candidates allow (after the first of them; at most MAX_SILENT_RUN lines of backlog given back)."""
    a = max(lo[i], prev_first + 1)
    b = min(hi[i], prev_last + (r[i] - r[i - 1]) + MAX_SILENT_RUN)
    return a, max(a, b)


@njit(cache=True)
def _forward(
    lo: IntArray,
    hi: IntArray,
    r: IntArray,
    t: FloatArray,
    has_on: npt.NDArray[np.bool_],
    note: IntArray,
    c1: FloatArray,
    c2: FloatArray,
    unk: FloatArray,
    early: FloatArray,
    late: FloatArray,
    motion: FloatArray,
    line_note: IntArray,
    o: float,
    scale: float,
    silent_cost: float,
    last_drain: int,
    m: int,
    keep: bool,
    bound: float,
) -> tuple[FloatArray, npt.NDArray[np.int32], IntArray, IntArray, float]:
    """Forward pass over the first m presses (stops with an infinite total once the best prefix
    costs more than `bound`: costs only grow).

    Returns the cost and back-pointer of every candidate (flat, press i's from off[i]; only when
    `keep`, else two alternating rows), each press's first candidate line, the offsets, and the
    best total. Candidates costlier than their press's best by BEAM are not extended.
    """
    top = 1
    for i in range(m):
        top = max(top, hi[i] - lo[i] + 1)
    size = 4 * m + 64 if keep else 2 * top
    forward = np.empty(size)
    back = np.zeros(size if keep else 1, dtype=np.int32)
    start = np.empty(m, dtype=np.int64)
    off = np.zeros(m + 1, dtype=np.int64)
    first_line, last_line = lo[0], hi[0]
    prev_width, prev_base, prev_best = 0, 0, math.inf
    for i in range(m):
        a, b = (lo[0], hi[0]) if i == 0 else _window(i, lo, hi, r, first_line, last_line)
        width = b - a + 1
        base = off[i] if keep else (i % 2) * top
        if keep and base + width > forward.size:
            grown = np.empty(2 * (base + width))
            grown[:base] = forward[:base]
            forward = grown
            grown_back = np.zeros(2 * (base + width), dtype=np.int32)
            grown_back[:base] = back[:base]
            back = grown_back
        best_here = math.inf
        for x in range(width):
            k = a + x
            if i == 0:
                best, arg = BACKLOG_COST * (r[0] - k), 0
            else:
                best, arg = math.inf, 0
                for y in range(prev_width):
                    kp = start[i - 1] + y
                    if kp >= k:
                        break
                    c = forward[prev_base + y]
                    if c > prev_best + BEAM:
                        continue
                    c += _pair(
                        i, kp, k, o, scale, t, has_on, c1, c2, unk, early, late, motion
                    ) + _backlog(i, kp, k, r)
                    if c < best:
                        best, arg = c, y
            value = best + _node(i, k, m, note, line_note, silent_cost, last_drain)
            forward[base + x] = value
            if keep:
                back[base + x] = arg
            best_here = min(best_here, value)
        start[i] = a
        off[i + 1] = off[i] + width
        first_line, last_line = b, a
        for x in range(width):
            if forward[base + x] <= best_here + BEAM:
                first_line = min(first_line, a + x)
                last_line = max(last_line, a + x)
        prev_width, prev_base, prev_best = width, base, best_here
        if best_here > bound:
            return forward, back, start, off, math.inf
    return forward, back, start, off, prev_best


@njit(cache=True)
def best_total(
    lo: IntArray,
    hi: IntArray,
    r: IntArray,
    t: FloatArray,
    has_on: npt.NDArray[np.bool_],
    note: IntArray,
    c1: FloatArray,
    c2: FloatArray,
    unk: FloatArray,
    early: FloatArray,
    late: FloatArray,
    motion: FloatArray,
    line_note: IntArray,
    o: float,
    scale: float,
    silent_cost: float,
    last_drain: int,
    m: int,
    bound: float,
) -> float:
    """Cost of the best assignment of the first m presses (for the profile over `o`); infinite
    when it exceeds `bound`."""
    total: float = _forward(
        lo,
        hi,
        r,
        t,
        has_on,
        note,
        c1,
        c2,
        unk,
        early,
        late,
        motion,
        line_note,
        o,
        scale,
        silent_cost,
        last_drain,
        m,
        False,
        bound,
    )[4]
    return total


@njit(cache=True)
def viterbi(
    lo: IntArray,
    hi: IntArray,
    r: IntArray,
    t: FloatArray,
    has_on: npt.NDArray[np.bool_],
    note: IntArray,
    c1: FloatArray,
    c2: FloatArray,
    unk: FloatArray,
    early: FloatArray,
    late: FloatArray,
    motion: FloatArray,
    line_note: IntArray,
    o: float,
    scale: float,
    silent_cost: float,
    last_drain: int,
) -> tuple[IntArray, FloatArray, FloatArray, IntArray, IntArray]:
    """Best line per press, its margin, the extra cost of its read line (inf when it was no
    candidate), the best alternative line, and the last candidate line of each press."""
    m = lo.size
    forward, back, start, off, _ = _forward(
        lo,
        hi,
        r,
        t,
        has_on,
        note,
        c1,
        c2,
        unk,
        early,
        late,
        motion,
        line_note,
        o,
        scale,
        silent_cost,
        last_drain,
        m,
        True,
        math.inf,
    )
    backward = np.zeros(off[m])
    for i in range(m - 1, 0, -1):
        best_prev = math.inf
        for y in range(off[i] - off[i - 1]):
            best_prev = min(best_prev, forward[off[i - 1] + y])
        for y in range(off[i] - off[i - 1]):
            kp = start[i - 1] + y
            best = math.inf
            if forward[off[i - 1] + y] <= best_prev + BEAM:
                for x in range(off[i + 1] - off[i]):
                    k = start[i] + x
                    if k <= kp:
                        continue
                    c = (
                        _pair(i, kp, k, o, scale, t, has_on, c1, c2, unk, early, late, motion)
                        + _backlog(i, kp, k, r)
                        + _node(i, k, m, note, line_note, silent_cost, last_drain)
                        + backward[off[i] + x]
                    )
                    if c < best:
                        best = c
            backward[off[i - 1] + y] = best
    keys = np.empty(m, dtype=np.int64)
    last = np.empty(m, dtype=np.int64)
    x = 0
    for j in range(off[m] - off[m - 1]):
        if forward[off[m - 1] + j] < forward[off[m - 1] + x]:
            x = j
    for i in range(m - 1, -1, -1):
        keys[i] = start[i] + x
        last[i] = start[i] + off[i + 1] - off[i] - 1
        if i > 0:
            x = back[off[i] + x]
    margin = np.full(m, math.inf)
    own = np.full(m, math.inf)
    alt = np.full(m, -1, dtype=np.int64)
    for i in range(m):
        chosen = keys[i] - start[i]
        total = forward[off[i] + chosen] + backward[off[i] + chosen]
        for x in range(off[i + 1] - off[i]):
            other = forward[off[i] + x] + backward[off[i] + x]
            if x != chosen and other - total < margin[i]:
                margin[i] = other - total
                alt[i] = start[i] + x
            if start[i] + x == r[i]:
                own[i] = other - total
    return keys, margin, own, alt, last


@njit(cache=True)
def pair_costs(
    keys: IntArray,
    o: float,
    scale: float,
    t: FloatArray,
    has_on: npt.NDArray[np.bool_],
    c1: FloatArray,
    c2: FloatArray,
    unk: FloatArray,
    early: FloatArray,
    late: FloatArray,
    motion: FloatArray,
) -> FloatArray:
    """Timing cost of each press with its predecessor under an assignment (0 for the first)."""
    out = np.zeros(keys.size)
    for i in range(1, keys.size):
        out[i] = _pair(
            i, keys[i - 1], keys[i], o, scale, t, has_on, c1, c2, unk, early, late, motion
        )
    return out
