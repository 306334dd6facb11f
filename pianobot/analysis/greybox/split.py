"""The one held-out split: whole keystrokes, stratified by vacuum level and speed.

Each vacuum level's keystrokes, in order of commanded speed (trial order when the speed was not
recorded), fall into groups of `every` neighbours, and one keystroke of each group is held out,
so both halves span every level and the whole speed range. The seed sets which one (seed 0: the
last of each group, as identification always did).

Where that leaves the training half without an outcome the log shows (no sounded keystroke to
learn the loudness from, or no silent one), the held-out position instead moves from one group
of differing commands to the next (`_digit_sum`). A fixed position picks the same inner grid
value every time: in the study's logs (3 accelerations x 15 speeds x 3 depths, depths innermost)
it holds out the 40 mm presses, and where only those sounded (a key a stiff preload held back),
the fits had nothing but silences to train on and moved none of their parameters. Moving it
spreads the held-out keystrokes over every combination of the inner values (5 of each of the 9
there). Groups of repetitions (one command `every` times) keep the fixed position either way.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from pianobot.analysis.greybox.keystrokes import COMMAND_FIELDS, KeystrokeBatch

IntArray = npt.NDArray[np.intp]
FloatArray = npt.NDArray[np.float64]

#: Commanded values closer than this (relative) are the same command: logs store floats with
#: their repr noise (0.045000000000000005).
SAME_COMMAND_RTOL = 1e-9


def holdout_indices(batch: KeystrokeBatch, every: int = 3, seed: int = 0) -> tuple[IntArray, IntArray]:
    """(train, held-out) row indices; both empty-safe (a batch too small to split is all train)."""
    if every < 2:
        raise ValueError(f"every should be >= 2, got {every}")
    train, test = _split(batch, every, seed, rotate=False)
    if _starved(batch, train):
        train, test = _split(batch, every, seed, rotate=True)
    if train.size == 0 or test.size == 0:
        return np.arange(batch.n, dtype=np.intp), np.zeros(0, dtype=np.intp)
    return train, test


def split_holdout(batch: KeystrokeBatch, every: int = 3, seed: int = 0) -> tuple[KeystrokeBatch, KeystrokeBatch]:
    """(train, held-out) batches; a batch too small to split is returned as both."""
    train, test = holdout_indices(batch, every, seed)
    if test.size == 0:
        return batch, batch
    return batch.subset(train), batch.subset(test)


def _split(batch: KeystrokeBatch, every: int, seed: int, *, rotate: bool) -> tuple[IntArray, IntArray]:
    """(train, held-out): one of each group of `every`, at the seed's position, or (`rotate`)
    moving from one group of differing commands to the next."""
    level = np.abs(batch.vacuum_kpa)
    speed = np.where(np.isfinite(batch.down_velocity_mps), batch.down_velocity_mps, 0.0)
    command = _commands(batch) if rotate else None
    phase = (every - 1 + seed) % every
    held: list[int] = []
    for p in sorted(set(level.tolist())):
        rows = np.flatnonzero(level == p)
        rows = rows[np.argsort(speed[rows], kind="stable")]
        varied = 0  # groups of differing commands seen so far in this level
        for start in range(0, rows.size, every):
            group = rows[start : start + every]
            position = phase
            if command is not None and not _repetitions(command[group]):
                position = (phase - _digit_sum(varied, every)) % every
                varied += 1
            if position < group.size:
                held.append(int(group[position]))
    test = np.array(sorted(held), dtype=np.intp)
    return np.setdiff1d(np.arange(batch.n), test).astype(np.intp), test


def _starved(batch: KeystrokeBatch, train: IntArray) -> bool:
    """True when the training rows lack an outcome (sounded, silent) that the batch has."""
    known = batch.sounded[np.isfinite(batch.sounded)]
    return any(bool((known == c).any()) and not bool((batch.sounded[train] == c).any()) for c in (0.0, 1.0))


def _digit_sum(k: int, base: int) -> int:
    """The sum of k's digits in `base`: the held-out position's shift for the k-th group of
    differing commands. It moves by one from group to group, and by one more after every `base`
    groups (and `base`² ...), so a grid nested `base` x `base` deep inside each speed is held out
    at each of its combinations, not along one diagonal."""
    total = 0
    while k:
        k, digit = divmod(k, base)
        total += digit
    return total


def _commands(batch: KeystrokeBatch) -> FloatArray:
    """(n, k): each keystroke's commanded press and start gap (NaN where not recorded)."""
    columns = [getattr(batch, name) for name in COMMAND_FIELDS] + [batch.distance_m]
    return np.stack([np.asarray(c, dtype=np.float64) for c in columns], axis=1)


def _repetitions(commands: FloatArray) -> bool:
    """True when every row repeats the first one's command (NaN matching NaN)."""
    first = commands[0]
    same = np.isclose(commands, first, rtol=SAME_COMMAND_RTOL, atol=0.0) | (np.isnan(commands) & np.isnan(first))
    return bool(same.all())
