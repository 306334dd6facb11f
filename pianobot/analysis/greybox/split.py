"""The one held-out split: whole keystrokes, stratified by vacuum level and speed.

Every `every`-th keystroke of each vacuum level, in order of commanded speed (trial order when
the speed was not recorded), is held out, so both halves span every level and the whole speed
range. The phase (which of the `every` is held out) comes from the seed; seed 0 holds out the
last of each group of `every` (the 3rd, 6th, ...), as identification always did.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from pianobot.analysis.greybox.keystrokes import KeystrokeBatch

IntArray = npt.NDArray[np.intp]


def holdout_indices(batch: KeystrokeBatch, every: int = 3, seed: int = 0) -> tuple[IntArray, IntArray]:
    """(train, held-out) row indices; both empty-safe (a batch too small to split is all train)."""
    if every < 2:
        raise ValueError(f"every should be >= 2, got {every}")
    level = np.abs(batch.vacuum_kpa)
    speed = np.where(np.isfinite(batch.down_velocity_mps), batch.down_velocity_mps, 0.0)
    phase = (every - 1 + seed) % every
    held: list[int] = []
    for p in sorted(set(level.tolist())):
        rows = np.flatnonzero(level == p)
        rows = rows[np.argsort(speed[rows], kind="stable")]
        held.extend(rows[phase::every].tolist())
    test = np.array(sorted(held), dtype=np.intp)
    train = np.setdiff1d(np.arange(batch.n), test).astype(np.intp)
    if train.size == 0 or test.size == 0:
        return np.arange(batch.n, dtype=np.intp), np.zeros(0, dtype=np.intp)
    return train, test


def split_holdout(batch: KeystrokeBatch, every: int = 3, seed: int = 0) -> tuple[KeystrokeBatch, KeystrokeBatch]:
    """(train, held-out) batches; a batch too small to split is returned as both."""
    train, test = holdout_indices(batch, every, seed)
    if test.size == 0:
        return batch, batch
    return batch.subset(train), batch.subset(test)
