"""Where in a keystroke the model misses: residuals summarised per stage, not one line per stroke.

Each keystroke is cut into the study's five stages; inside each stage its time is scaled to
[0, 1), so keystrokes of different speeds line up stage by stage. Over all keystrokes the
figure shows the median residual and the band holding the middle 80 % of them, and the table
gives per stage the keystrokes seen, the median stage duration, the median residual, its RMS and
the 90th percentile of its size. A band away from zero in one stage points at physics the model
lacks there (the keybed in "bottom", friction or preload in "contact").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.analysis.greybox.stages import STAGE_NAMES, find_stages
from pianobot.reports.style import percentile_band

FloatArray = npt.NDArray[np.float64]

#: Points per stage on the scaled time axis (a stage lasts 0.05–2 s; 120 Hz mocap).
POINTS_PER_STAGE = 25


def stage_edges(t_s: FloatArray, x0: FloatArray, x1: FloatArray, x2: FloatArray,
                distance_m: float) -> FloatArray:
    """The six stage boundaries (s) of traces that are relative to rest (0 = at rest).

    A sweep's traces start at motion start, so they hold no sample at rest to estimate a rest
    level from; they are relative to rest already and `find_stages` is told so.
    """
    t = np.asarray(t_s, dtype=np.float64)
    found = find_stages(t, x2, x0_m=x0, x1_m=x1, distance_m=distance_m if distance_m > 0 else None,
                        relative_to_rest=True)
    return np.asarray(np.maximum(found.boundaries_s, t[0]), dtype=np.float64)


@dataclass(frozen=True)
class StageResiduals:
    """Residuals (measured − model) of many keystrokes on the stage-scaled time axis."""

    phase: FloatArray  # (5 * POINTS_PER_STAGE,): stage index + fraction of the stage
    median_m: FloatArray
    low_m: FloatArray  # 10th percentile over keystrokes
    high_m: FloatArray  # 90th percentile
    keystrokes: FloatArray  # how many keystrokes have a residual at each point
    table: pd.DataFrame  # one row per stage (see `stage_residuals`)

    @property
    def empty(self) -> bool:
        return not np.isfinite(self.median_m).any()


def stage_residuals(t_s: list[FloatArray], x0: FloatArray, x1: FloatArray, x2: FloatArray,
                    x2_model: FloatArray, distance_m: FloatArray) -> StageResiduals:
    """Residuals of keystroke rows (each with its own sample times) by stage.

    Args:
        t_s: per keystroke, its sample times (s).
        x0, x1, x2: measured traces (n, T), relative to rest, NaN where not measured.
        x2_model: the model's key trace (n, T), NaN where the model does not apply.
        distance_m: per keystroke, the fingertip's start height above the key.

    Returns:
        The band and a table with, per stage: stage, keystrokes, median duration (s), median
        residual (m), RMS residual (m), 90th percentile of |residual| (m).
    """
    n = len(t_s)
    k = POINTS_PER_STAGE
    frac = (np.arange(k) + 0.5) / k
    grid = np.full((n, len(STAGE_NAMES) * k), np.nan)
    pooled: list[list[FloatArray]] = [[] for _ in STAGE_NAMES]
    durations: list[list[float]] = [[] for _ in STAGE_NAMES]
    for i in range(n):
        t = np.asarray(t_s[i], dtype=np.float64)
        residual = x2[i] - x2_model[i]
        if not np.isfinite(residual).any():
            continue
        edges = stage_edges(t, x0[i], x1[i], x2[i], float(distance_m[i]))
        for s in range(len(STAGE_NAMES)):
            a, b = edges[s], edges[s + 1]
            if not (np.isfinite(a) and np.isfinite(b) and b > a):
                continue
            durations[s].append(float(b - a))
            # Nearest sample, not interpolation: a dropped frame stays a gap, never invented.
            at = np.clip(np.searchsorted(t, a + frac * (b - a)), 0, t.size - 1)
            grid[i, s * k:(s + 1) * k] = residual[at]
            inside = residual[(t >= a) & (t < b)]
            pooled[s].append(inside[np.isfinite(inside)])
    median, low, high, count = percentile_band(grid)
    rows = []
    for s, name in enumerate(STAGE_NAMES):
        values = np.concatenate(pooled[s]) if pooled[s] else np.zeros(0)
        seen = int(sum(1 for v in pooled[s] if v.size))
        rows.append({
            "stage": f"{s + 1} {name}",
            "keystrokes": seen,
            "median_duration_s": float(np.median(durations[s])) if durations[s] else np.nan,
            "median_residual_m": float(np.median(values)) if values.size else np.nan,
            "rms_residual_m": float(np.sqrt(np.mean(values**2))) if values.size else np.nan,
            "p90_abs_residual_m": float(np.percentile(np.abs(values), 90)) if values.size else np.nan,
        })
    phase = np.concatenate([s + frac for s in range(len(STAGE_NAMES))])
    return StageResiduals(phase, median, low, high, count, pd.DataFrame(rows))
