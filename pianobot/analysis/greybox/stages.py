"""The study's five keystroke stages, found in arm, fingertip and key traces.

The stages (Zhang et al. 2022, five-stage keystroke figure):

1. approach — the arm moves, the fingertip has not reached the key;
2. contact  — the fingertip touches the key and compresses (and may slip) before the key moves:
   the key needs its preload force before it leaves the rest stop;
3. press    — the key travels down;
4. bottom   — the key sits at (or near) the bottom of its travel while the arm holds/reverses;
5. release  — the key returns to rest and the finger lifts off.

Traces may be measured (mocap, NaN for dropped frames) or simulated. Any of x1 (fingertip) or
x0 (arm) may be missing; the key trace x2 is required. Coordinates are downward positive.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

STAGE_NAMES: tuple[str, ...] = ("approach", "contact", "press", "bottom", "release")

#: Below this the key counts as "at rest": mocap noise is a few µm, key dip ~10 mm.
KEY_MOTION_THRESHOLD_M = 2.0e-4
#: The key is "at the bottom" while within this fraction of its maximum travel.
BOTTOM_FRACTION = 0.9


@dataclass(frozen=True)
class Stages:
    """Boundary times (s, on the trace's clock) of the five stages; NaN when a stage is absent."""

    t_motion_s: float  # arm starts moving (start of approach)
    t_contact_s: float  # fingertip reaches the key
    t_key_move_s: float  # key leaves its rest position
    t_bottom_s: float  # key reaches the bottom band
    t_release_s: float  # key leaves the bottom band on the way up
    t_rest_s: float  # key back at rest (end of release)

    @property
    def boundaries_s(self) -> FloatArray:
        """The six boundary times in order."""
        return np.array(list(asdict(self).values()), dtype=np.float64)

    def label(self, t_s: npt.ArrayLike) -> npt.NDArray[np.str_]:
        """Stage name for each time ("" outside every stage)."""
        t = np.asarray(t_s, dtype=np.float64)
        out = np.full(t.shape, "", dtype="<U8")
        edges = self.boundaries_s
        for i, name in enumerate(STAGE_NAMES):
            lo, hi = edges[i], edges[i + 1]
            if np.isfinite(lo) and np.isfinite(hi):
                out[(t >= lo) & (t < hi)] = name
        return out


def fill_gaps(t_s: FloatArray, x: FloatArray) -> FloatArray:
    """Linear interpolation over NaN samples (edges held); all-NaN stays all-NaN."""
    x = np.asarray(x, dtype=np.float64)
    good = np.isfinite(x)
    if good.all() or not good.any():
        return x.copy()
    return np.interp(t_s, t_s[good], x[good])


def first_crossing_s(t_s: FloatArray, x: FloatArray, level: float, start: int = 0) -> float:
    """Time x first rises through `level` at or after sample `start` (linear interpolation)."""
    above = np.flatnonzero(x[start:] >= level)
    if above.size == 0:
        return float("nan")
    i = start + int(above[0])
    if i == 0 or not np.isfinite(x[i - 1]) or x[i - 1] >= level:
        return float(t_s[i])
    frac = (level - x[i - 1]) / (x[i] - x[i - 1])
    return float(t_s[i - 1] + frac * (t_s[i] - t_s[i - 1]))


def _last_crossing_down_s(t_s: FloatArray, x: FloatArray, level: float, start: int) -> float:
    """Time x first falls below `level` at or after sample `start`."""
    below = np.flatnonzero(x[start:] < level)
    if below.size == 0:
        return float("nan")
    i = start + int(below[0])
    if i == 0 or x[i - 1] < level:
        return float(t_s[i])
    frac = (x[i - 1] - level) / (x[i - 1] - x[i])
    return float(t_s[i - 1] + frac * (t_s[i] - t_s[i - 1]))


def rest_level(t_s: FloatArray, x: FloatArray) -> float:
    """The rest level of a trace: the median before motion start (t < 0) if recorded, else its
    first finite sample.

    Times are relative to motion start, so samples at t < 0 are at rest; a trace that starts at
    t = 0 is surely at rest only at its first sample (at 120 frames/s the next one is 8 ms into
    the motion, when an arm accelerating at 1 m/s² has already moved 35 µm). The one rule for
    every trace the analysis references to rest; NaN when the trace has no finite sample.
    """
    t = np.asarray(t_s, dtype=np.float64)
    v = np.asarray(x, dtype=np.float64)
    finite = np.isfinite(v)
    before = finite & (t < 0.0)
    if before.any():
        return float(np.median(v[before]))
    if not finite.any():
        return float("nan")
    return float(v[np.argmax(finite)])


def find_stages(
    t_s: npt.ArrayLike,
    x2_m: npt.ArrayLike,
    *,
    x0_m: npt.ArrayLike | None = None,
    x1_m: npt.ArrayLike | None = None,
    distance_m: float | None = None,
    key_threshold_m: float = KEY_MOTION_THRESHOLD_M,
    relative_to_rest: bool = False,
) -> Stages:
    """Find the five stages of one keystroke.

    Args:
        t_s: sample times (increasing).
        x2_m: key displacement (downward positive); NaN samples are interpolated over.
        x0_m: arm displacement, if known; gives the start of motion.
        x1_m: fingertip displacement, if known; with `distance_m` gives the contact instant.
        distance_m: initial fingertip–key gap; None or 0 means the finger starts on the key.
        key_threshold_m: key travel that counts as "moving" (above the measurement noise).
        relative_to_rest: the traces are already relative to rest (0 = at rest), so no rest level
            is estimated from them (`rest_level` would take a trace that starts at motion start
            from its first finite sample).
    """
    t = np.asarray(t_s, dtype=np.float64)
    x2 = fill_gaps(t, np.asarray(x2_m, dtype=np.float64))
    nan = float("nan")
    if t.size < 3 or not np.isfinite(x2).any():
        return Stages(nan, nan, nan, nan, nan, nan)
    if not relative_to_rest:
        x2 = x2 - rest_level(t, x2)

    t_motion = float(t[0])
    if x0_m is not None:
        x0 = fill_gaps(t, np.asarray(x0_m, dtype=np.float64))
        if np.isfinite(x0).any():
            if not relative_to_rest:
                x0 = x0 - rest_level(t, x0)
            travel = float(np.nanmax(x0))
            # 2 % of the stroke (at least the key threshold) separates motion from noise.
            level = max(key_threshold_m, 0.02 * travel)
            t_found = first_crossing_s(t, x0, level)
            if np.isfinite(t_found):
                t_motion = t_found

    i_peak = int(np.nanargmax(x2))
    travel2 = float(x2[i_peak])
    if travel2 < key_threshold_m:  # the key never moved: approach only, no other stage
        return Stages(t_motion, nan, nan, nan, nan, nan)

    t_key_move = first_crossing_s(t, x2, key_threshold_m)
    t_contact = t_key_move
    if x1_m is not None and distance_m is not None and distance_m > 0:
        x1 = fill_gaps(t, np.asarray(x1_m, dtype=np.float64))
        if np.isfinite(x1).any():
            gap_closed = (x1 if relative_to_rest else x1 - rest_level(t, x1)) - x2
            t_found = first_crossing_s(t, gap_closed, distance_m - key_threshold_m)
            if np.isfinite(t_found) and t_found <= t_key_move:
                t_contact = t_found
    elif distance_m is None or distance_m <= 0:
        t_contact = t_motion if t_motion <= t_key_move else t_key_move

    bottom_level = BOTTOM_FRACTION * travel2
    t_bottom = first_crossing_s(t, x2, bottom_level)
    t_release = _last_crossing_down_s(t, x2, bottom_level, i_peak)
    i_release = int(np.searchsorted(t, t_release)) if np.isfinite(t_release) else t.size - 1
    t_rest = _last_crossing_down_s(t, x2, key_threshold_m, min(i_release, t.size - 1))
    if np.isnan(t_rest):
        t_rest = float(t[-1])
    if np.isnan(t_release):
        t_release = float(t[-1])
    return Stages(t_motion, t_contact, t_key_move, t_bottom, t_release, t_rest)


def stage_labels(t_s: FloatArray, x2_m: FloatArray, x0_m: FloatArray | None = None,
                 x1_m: FloatArray | None = None, distance_m: FloatArray | None = None) -> npt.NDArray[np.int64]:
    """Stage index (into `STAGE_NAMES`) of every sample of keystrokes (rows), −1 outside all.

    Args:
        t_s: (n, T) sample times of each row, or (T,) shared.
        x2_m, x0_m, x1_m: (n, T) key, arm and fingertip (relative to rest; NaN not measured).
        distance_m: (n,) fingertip-key gap at the start.
    """
    x2 = np.atleast_2d(np.asarray(x2_m, dtype=np.float64))
    n, T = x2.shape
    t = np.broadcast_to(np.asarray(t_s, dtype=np.float64), (n, T))
    out = np.full((n, T), -1, dtype=np.int64)
    for i in range(n):
        stages = find_stages(
            t[i], x2[i], x0_m=None if x0_m is None else x0_m[i], x1_m=None if x1_m is None else x1_m[i],
            distance_m=None if distance_m is None else float(distance_m[i]))
        names = stages.label(t[i])
        for k, name in enumerate(STAGE_NAMES):
            out[i, names == name] = k
    return out
