"""Segmenting a mocap take into keystrokes (one per press of the arm marker).

Each press is a down-and-up excursion of the arm. The arm's downward displacement is measured
from a slowly varying rest level (a rolling low percentile, so a mocap drift of a fraction of a
millimetre over minutes does not bias the travel); short occlusions are bridged by linear
interpolation. A press is a stretch above half of the typical excursion (hysteresis: it extends to
where the displacement falls below 10 %), so micrometre noise and a dropped frame cannot split or
invent one. Per press:

- motion start/end: where the arm leaves / regains its rest level (within a few noise SDs);
- arm travel: median displacement over the bottom plateau (frames above 80 % of the maximum);
- arm speed: median speed over the steady part of the descent (speeds ≥ 80 % of the 90th
  percentile), which skips the moveL acceleration and braking phases;
- key / fingertip travel: maximum displacement relative to their own rest just before the press;
  key speed: the maximum downward key speed during the press.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.io.mocap import MocapTake

FloatArray = npt.NDArray[np.float64]
KEYSTROKE_COLUMNS = (
    "keystroke", "t_start_s", "t_bottom_s", "t_end_s", "duration_s", "arm_travel_m",
    "arm_speed_mps", "fingertip_travel_m", "key_travel_m", "key_speed_mps", "key_rest_m",
    "key_rest_after_m",
)  # fmt: skip
REST_WINDOW_S = 0.25  # rest level of fingertip and key: median over this long before motion start
MAX_BRIDGE_S = 0.5  # occlusions up to this long are interpolated for segmentation


def segment_take(take: MocapTake, baseline_window_s: float = 10.0) -> pd.DataFrame:
    """One row per press of the arm marker (columns `KEYSTROKE_COLUMNS`, SI units)."""
    arm = take.down_m("arm")
    if arm is None or np.isfinite(arm).sum() < 10:
        return pd.DataFrame(columns=list(KEYSTROKE_COLUMNS))
    t = take.t_s
    filled = bridge(t, arm, MAX_BRIDGE_S)
    rest = rolling_rest(filled, max(3, int(baseline_window_s * take.frame_rate_hz)))
    lift = filled - rest
    spans = excursions(lift)
    noise = _noise_sd(lift)
    tip, key = take.down_m("fingertip"), take.down_m("key")
    rows = []
    for n, (i0, i1) in enumerate(spans):
        depth = lift[i0:i1]
        peak = float(np.nanmax(depth))
        settle = max(5 * noise, 0.02 * peak)
        start = i0
        while start > 0 and np.isfinite(lift[start - 1]) and lift[start - 1] > settle:
            start -= 1
        end = i1
        while end < lift.size - 1 and np.isfinite(lift[end]) and lift[end] > settle:
            end += 1
        bottom = i0 + int(np.nanargmax(depth))
        row = {
            "keystroke": n,
            "t_start_s": float(t[start]),
            "t_bottom_s": float(t[bottom]),
            "t_end_s": float(t[end]),
            "duration_s": float(t[end] - t[start]),
            "arm_travel_m": float(np.nanmedian(depth[depth >= 0.8 * peak])),
            "arm_speed_mps": descent_speed(t[start : bottom + 1], lift[start : bottom + 1]),
            "fingertip_travel_m": _travel(t, tip, start, end),
            "key_travel_m": _travel(t, key, start, end),
            "key_speed_mps": _peak_speed(t, key, start, end),
            "key_rest_m": _below_arm(t, key, arm, start),
            "key_rest_after_m": _below_arm(t, key, arm, end, after=True),
        }
        rows.append(row)
    return pd.DataFrame(rows, columns=list(KEYSTROKE_COLUMNS))


def bridge(t: FloatArray, x: FloatArray, max_gap_s: float) -> FloatArray:
    """Linear interpolation across NaN runs no longer than `max_gap_s` (longer ones stay NaN)."""
    out = x.copy()
    good = np.isfinite(x)
    if good.sum() < 2:
        return out
    filled = np.interp(t, t[good], x[good])
    for before, after in gaps(x):
        if before >= 0 and after < x.size and t[after] - t[before] <= max_gap_s:
            out[before + 1 : after] = filled[before + 1 : after]
    return out


def gaps(x: FloatArray) -> list[tuple[int, int]]:
    """Each run of NaN in `x` as (the sample before it, the sample after it): -1 or `x.size`
    where the run touches an end."""
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size == 0:
        return []
    return [(int(run[0]) - 1, int(run[-1]) + 1) for run in np.split(bad, np.flatnonzero(np.diff(bad) > 1) + 1)]


def unseen_spans(take: MocapTake) -> list[tuple[float, float]]:
    """(from, to) times, between the arm marker's first and last frames, where it is lost for
    longer than segmentation bridges (`MAX_BRIDGE_S`): a press there cannot be segmented."""
    arm = take.down_m("arm")
    if arm is None:
        return []
    t = take.t_s
    return [(float(t[before]), float(t[after])) for before, after in gaps(arm)
            if before >= 0 and after < arm.size and t[after] - t[before] > MAX_BRIDGE_S]


def rolling_rest(x: FloatArray, window: int) -> FloatArray:
    """Rest level: rolling 10th percentile (presses are brief dips below the rest the arm keeps)."""
    series = pd.Series(x)
    low = series.rolling(window, center=True, min_periods=1).quantile(0.1)
    return low.rolling(window, center=True, min_periods=1).median().to_numpy(dtype=np.float64)


def excursions(lift: FloatArray, high: float = 0.5, low: float = 0.1) -> list[tuple[int, int]]:
    """[start, end) index spans where `lift` rises above `high`·A, extended down to `low`·A.

    A is the typical excursion: the 99th percentile of `lift`.
    """
    finite = lift[np.isfinite(lift)]
    if finite.size == 0:
        return []
    amplitude = float(np.percentile(finite, 99))
    if not amplitude > 0:
        return []
    above = np.nan_to_num(lift, nan=0.0) > high * amplitude
    spans: list[tuple[int, int]] = []
    i = 0
    while i < lift.size:
        if not above[i]:
            i += 1
            continue
        start = i
        while start > 0 and np.nan_to_num(lift[start - 1]) > low * amplitude:
            start -= 1
        end = i
        while end < lift.size and np.nan_to_num(lift[end]) > low * amplitude:
            end += 1
        if spans and start <= spans[-1][1]:
            spans[-1] = (spans[-1][0], max(end, spans[-1][1]))
        elif end - start >= 3:
            spans.append((start, end))
        i = end + 1
    return spans


def descent_speed(t: FloatArray, x: FloatArray) -> float:
    """Median speed over the steady part of a descent (speeds ≥ 80 % of the 90th percentile)."""
    good = np.isfinite(x)
    if good.sum() < 3:
        return math.nan
    v = np.gradient(x[good], t[good])
    top = float(np.percentile(v, 90))
    if not top > 0:
        return math.nan
    return float(np.median(v[v >= 0.8 * top]))


def _noise_sd(lift: FloatArray) -> float:
    """Frame-to-frame noise SD from the MAD of first differences (robust to the presses)."""
    d = np.diff(lift[np.isfinite(lift)])
    if d.size == 0:
        return 0.0
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2))


def rest_level_before(t: FloatArray, x: FloatArray, start: int) -> float:
    """Median of `x` over REST_WINDOW_S before frame `start` (or the first frames of the take)."""
    window = (t >= t[start] - REST_WINDOW_S) & (t <= t[start])
    values = x[window & np.isfinite(x)]
    if values.size == 0:
        values = x[np.isfinite(x)][:10]
    return float(np.median(values)) if values.size else math.nan


def _below_arm(t: FloatArray, x: FloatArray | None, arm: FloatArray, frame: int, after: bool = False) -> float:
    """How far `x` rests below the arm marker before frame `frame` (`after`: after it), down
    positive. The arm returns to one pose between presses and a drift of the whole capture
    volume moves both markers alike, so a change of this along a take is the marker's own (a
    key left down) or the arm's."""
    if x is None:
        return math.nan
    level = rest_level_after if after else rest_level_before
    return level(t, x, frame) - level(t, arm, frame)


def rest_level_after(t: FloatArray, x: FloatArray, end: int) -> float:
    """Median of `x` over REST_WINDOW_S after frame `end` (NaN without a finite frame there)."""
    values = x[(t >= t[end]) & (t <= t[end] + REST_WINDOW_S) & np.isfinite(x)]
    return float(np.median(values)) if values.size else math.nan


def _travel(t: FloatArray, x: FloatArray | None, start: int, end: int) -> float:
    if x is None:
        return math.nan
    segment = x[start : end + 1]
    if not np.isfinite(segment).any():
        return math.nan
    return float(np.nanmax(segment) - rest_level_before(t, x, start))


def _peak_speed(t: FloatArray, x: FloatArray | None, start: int, end: int) -> float:
    if x is None:
        return math.nan
    segment, times = x[start : end + 1], t[start : end + 1]
    good = np.isfinite(segment)
    if good.sum() < 3:
        return math.nan
    return float(np.max(np.gradient(segment[good], times[good])))
