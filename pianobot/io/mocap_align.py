"""Clock alignment of a mocap take to a run: cross-correlate the arm marker with the arm trace.

The run's arm samples (source "arm", t_s from each trial's motion start) are laid on the run clock
(t_start_s + t_s) and both signals are resampled on one uniform grid, with their rest level
removed and gaps set to zero. The lag maximising their cross-correlation (refined to a fraction
of a sample with a parabola through the peak) is the clock offset: run time = mocap time +
clock_offset_s. When the run has no arm trace, the offset is the one that lines up most mocap
keystroke starts with the trials' motion starts (median of the matched differences).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class ClockAlignment:
    """run time = mocap time + clock_offset_s; `score` is the peak normalised correlation."""

    clock_offset_s: float
    score: float
    method: str  # "arm-xcorr" | "keystroke-starts"


def run_arm_trace(trials: pd.DataFrame, samples: pd.DataFrame) -> tuple[FloatArray, FloatArray]:
    """The run's arm displacement on the run clock (time-sorted), from samples with source arm."""
    if samples.empty or "source" not in samples:
        return np.empty(0), np.empty(0)
    arm = samples[(samples["source"] == "arm") & samples["x0_m"].notna()]
    starts = trials.drop_duplicates("trial_id", keep="last").set_index("trial_id")["t_start_s"]
    t = arm["t_s"].to_numpy(dtype=np.float64) + arm["trial_id"].map(starts).to_numpy(
        dtype=np.float64
    )
    x = arm["x0_m"].to_numpy(dtype=np.float64)
    good = np.isfinite(t) & np.isfinite(x)
    order = np.argsort(t[good])
    return t[good][order], x[good][order]


def xcorr_offset(
    t_ref: FloatArray, x_ref: FloatArray, t_mocap: FloatArray, x_mocap: FloatArray, dt_s: float
) -> ClockAlignment | None:
    """Offset such that x_ref(t) ≈ x_mocap(t − offset), by cross-correlation on a `dt_s` grid."""
    if t_ref.size < 4 or np.isfinite(x_mocap).sum() < 4:
        return None
    ref = _grid(t_ref, x_ref, dt_s)
    moc = _grid(t_mocap[np.isfinite(x_mocap)], x_mocap[np.isfinite(x_mocap)], dt_s)
    a, b = ref[1], moc[1]
    n = int(2 ** math.ceil(math.log2(a.size + b.size)))
    corr = np.fft.irfft(np.fft.rfft(a, n) * np.conj(np.fft.rfft(b, n)), n)
    lags = np.concatenate([np.arange(0, a.size), np.arange(-(b.size - 1), 0)])
    corr = np.concatenate([corr[: a.size], corr[n - (b.size - 1) :]])
    best = int(np.argmax(corr))
    shift = float(lags[best])
    if (
        0 < best < corr.size - 1
        and lags[best - 1] == lags[best] - 1
        and lags[best + 1] == lags[best] + 1
    ):
        y0, y1, y2 = corr[best - 1], corr[best], corr[best + 1]
        denominator = y0 - 2 * y1 + y2
        if denominator < 0:
            shift += 0.5 * (y0 - y2) / denominator
    norm = float(np.sqrt(np.sum(a * a) * np.sum(b * b)))
    score = float(corr[best] / norm) if norm > 0 else 0.0
    offset = ref[0] - moc[0] + shift * dt_s
    return ClockAlignment(offset, score, "arm-xcorr")


def _grid(t: FloatArray, x: FloatArray, dt_s: float) -> tuple[float, FloatArray]:
    """Start time and values on a uniform grid; rest level (median) removed, gaps > 2 dt zeroed."""
    start = float(t[0])
    times = np.arange(start, float(t[-1]) + dt_s / 2, dt_s)
    values = np.interp(times, t, x) - float(np.median(x))
    index = np.searchsorted(t, times)
    near = np.minimum(
        np.abs(t[np.clip(index, 0, t.size - 1)] - times),
        np.abs(t[np.clip(index - 1, 0, t.size - 1)] - times),
    )
    values[near > 2 * dt_s] = 0.0
    return start, values


def starts_offset(
    trial_starts_s: FloatArray, keystroke_starts_s: FloatArray, tolerance_s: float = 0.15
) -> ClockAlignment | None:
    """Offset lining up most keystroke starts with trial starts (then the median difference)."""
    trials = np.sort(trial_starts_s[np.isfinite(trial_starts_s)])
    strokes = np.sort(keystroke_starts_s[np.isfinite(keystroke_starts_s)])
    if trials.size == 0 or strokes.size == 0:
        return None
    best: tuple[int, float] | None = None
    for candidate in (trials[:, None] - strokes[None, :5]).ravel():  # the first strokes suffice
        shifted = strokes + candidate
        nearest = trials[np.clip(np.searchsorted(trials, shifted), 0, trials.size - 1)]
        previous = trials[np.clip(np.searchsorted(trials, shifted) - 1, 0, trials.size - 1)]
        gap = np.minimum(np.abs(nearest - shifted), np.abs(previous - shifted))
        hits = int((gap < tolerance_s).sum())
        if best is None or hits > best[0]:
            best = (hits, float(candidate))
    assert best is not None
    shifted = strokes + best[1]
    index = np.clip(np.searchsorted(trials, shifted), 0, trials.size - 1)
    candidates = np.stack([trials[index], trials[np.clip(index - 1, 0, trials.size - 1)]])
    nearest = candidates[np.argmin(np.abs(candidates - shifted), axis=0), np.arange(shifted.size)]
    close = np.abs(nearest - shifted) < tolerance_s
    offset = best[1] + float(np.median((nearest - shifted)[close])) if close.any() else best[1]
    return ClockAlignment(offset, best[0] / strokes.size, "keystroke-starts")
