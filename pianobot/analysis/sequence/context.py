"""Context features: what the last k strokes of a sequence tell about this one.

For lag j = 1..k each row gets the j-th previous stroke's controls, its outcome (on-velocity,
silent, MIDI hold) and its on-velocity residual against the context-free model (outcome minus
what the stroke alone predicts: a finger that is stiffer than usual in this sequence, or a key
still moving, shows up there). With k ≥ 1 a row also gets the pitch step from the previous
stroke (the sideways move). Strokes near the start of a sequence have fewer predecessors; the
missing lags are NaN, which the gradient-boosted trees route on their own.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd

FloatArray = npt.NDArray[np.float64]

#: Outcomes of a previous stroke that enter the context (besides its residual).
OUTCOMES: tuple[str, ...] = ("on_velocity", "silent", "midi_hold_s")


def feature_names(controls: tuple[str, ...], k: int) -> list[str]:
    """Column names of `features(…, k)`, in order."""
    names = list(controls)
    if k >= 1:
        names += ["base_on_velocity", "note_step"]
    for j in range(1, k + 1):
        names += [f"prev{j}_{c}" for c in (*controls, *OUTCOMES, "residual")]
    return names


def features(frame: pd.DataFrame, controls: tuple[str, ...], k: int, base_on: FloatArray,
             residual: FloatArray) -> FloatArray:
    """The model matrix of every stroke in `frame` (sorted by sequence and order).

    `base_on`: the context-free on-velocity of each stroke; `residual`: each stroke's observed
    on-velocity minus its context-free prediction (NaN when silent).
    """
    own = frame[list(controls)].to_numpy(float)
    if k == 0:
        return own
    seq = frame["sequence"].to_numpy()
    parts = [own, base_on[:, None]]
    note = frame["note"].to_numpy(float)
    parts.append((note - _shift(note, seq, 1))[:, None])
    lagged = np.column_stack([own, frame[list(OUTCOMES)].to_numpy(float), residual])
    for j in range(1, k + 1):
        parts.append(_shift(lagged, seq, j))
    return np.column_stack(parts)


def _shift(values: npt.NDArray[np.float64], seq: npt.NDArray[np.int64], lag: int) -> FloatArray:
    """`values` moved down by `lag` rows within each sequence (NaN where there is no such row)."""
    out = np.full(values.shape, np.nan)
    if lag < len(values):
        out[lag:] = values[:-lag]
        same = np.zeros(len(values), bool)
        same[lag:] = seq[lag:] == seq[:-lag]
        out[~same] = np.nan
    return out
