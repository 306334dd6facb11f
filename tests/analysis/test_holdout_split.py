"""The held-out split: stratified by level and speed; never one that leaves the training half
without an outcome the log shows."""

from __future__ import annotations

from collections import Counter
from itertools import product

import numpy as np

from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.analysis.greybox.split import holdout_indices

SPEEDS = np.linspace(0.01, 0.08, 15)


def _log(rows: list[tuple[float, float, float]], *, vacuum: float = -60.0, noise: bool = False,
         sounds_from_m: float = 0.0) -> KeystrokeBatch:
    """A MIDI-only batch of (acceleration, speed, depth) rows in log order; the presses at least
    `sounds_from_m` deep sounded."""
    acc, speed, depth = (np.array(c, dtype=float) for c in zip(*rows, strict=True))
    if noise:  # the study's logs keep the float repr noise of their grid
        speed = speed + 1e-17
    n = len(rows)
    return KeystrokeBatch(tuple(f"k{i}" for i in range(n)), np.full(n, vacuum), np.zeros(0), np.zeros((n, 0)),
                          np.zeros((n, 0)), np.zeros((n, 0)), distance_m=np.full(n, 0.05),
                          down_velocity_mps=speed, acceleration_mps2=acc, depth_m=depth, hold_s=np.zeros(n),
                          sounded=(depth >= sounds_from_m - 1e-9).astype(float))


def _study_grid(noise: bool = False, sounds_from_m: float = 0.0) -> KeystrokeBatch:
    """The study's ctrl_midi grid: acceleration outermost, then speed, depth innermost."""
    return _log([(a, v, d) for a, v, d in product((0.1, 0.5, 1.0), SPEEDS, (0.02, 0.03, 0.04))], noise=noise,
                sounds_from_m=sounds_from_m)


def test_a_grid_log_where_every_press_sounded_splits_as_before() -> None:
    batch = _study_grid()
    _, held = holdout_indices(batch)
    assert held.tolist() == list(range(2, batch.n, 3))  # the depth is the innermost loop: 40 mm


def test_a_log_where_only_the_deepest_presses_sound_holds_out_every_depth_alike() -> None:
    # The fixed position held out exactly the 40 mm presses: the training half had no sounded
    # keystroke, and the fits had only silences to learn from.
    for noise in (False, True):
        batch = _study_grid(noise, sounds_from_m=0.04)
        train, held = holdout_indices(batch)
        assert held.size == 45 and train.size == 90
        # Before, every held-out keystroke was a 40 mm press (the depth is the innermost loop).
        assert Counter(np.round(batch.depth_m[held], 3).tolist()) == {0.02: 15, 0.03: 15, 0.04: 15}
        assert Counter(batch.acceleration_mps2[held].tolist()) == {0.1: 15, 0.5: 15, 1.0: 15}
        # Still one in three at every speed.
        assert set(Counter(np.round(batch.down_velocity_mps[held], 4).tolist()).values()) == {3}
        pairs = Counter(zip(batch.acceleration_mps2[held].tolist(), np.round(batch.depth_m[held], 3).tolist(), strict=True))
        assert set(pairs.values()) == {5} and len(pairs) == 9  # every (acceleration, depth), alike


        assert batch.sounded[train].sum() == 30 and batch.sounded[held].sum() == 15


def test_a_log_where_only_the_shallow_presses_stayed_silent_trains_on_silent_ones() -> None:
    batch = _study_grid(sounds_from_m=0.03)
    batch = KeystrokeBatch(**{**batch.__dict__, "sounded": 1.0 - np.isclose(batch.depth_m, 0.04)})
    train, held = holdout_indices(batch)
    assert (batch.sounded[train] == 0.0).sum() == 30


def test_repeated_presses_split_as_before() -> None:
    # A take: 8 speeds x 3 repetitions of one command. Which repetition is held out does not
    # matter, and the rule is the one identification always used (the last of each 3; the seed
    # moves it).
    rows = [(1.0, v, 0.007) for v in np.linspace(0.01, 0.08, 8) for _ in range(3)]
    batch = _log(rows)
    for seed in range(3):
        _, held = holdout_indices(batch, 3, seed)
        assert held.tolist() == list(range((2 + seed) % 3, 24, 3))


def test_keystrokes_without_a_recorded_command_split_in_trial_order() -> None:
    n = 24
    batch = KeystrokeBatch(tuple(str(i) for i in range(n)), np.full(n, -40.0), np.zeros(0), np.zeros((n, 0)),
                           np.zeros((n, 0)), np.zeros((n, 0)))
    train, held = holdout_indices(batch)
    assert held.tolist() == list(range(2, n, 3)) and train.size == 16


def test_levels_are_split_apart() -> None:
    grid = [(a, v, d) for a, v, d in product((0.5, 1.0), SPEEDS[:6], (0.02, 0.03, 0.04))]
    rows = _log(grid, vacuum=-20.0, sounds_from_m=0.04), _log(grid, vacuum=-80.0, sounds_from_m=0.04)
    batch = KeystrokeBatch(
        tuple(f"k{i}" for i in range(72)), np.concatenate([r.vacuum_kpa for r in rows]), np.zeros(0),
        np.zeros((72, 0)), np.zeros((72, 0)), np.zeros((72, 0)), distance_m=np.full(72, 0.05),
        down_velocity_mps=np.concatenate([r.down_velocity_mps for r in rows]),
        acceleration_mps2=np.concatenate([r.acceleration_mps2 for r in rows]),
        depth_m=np.concatenate([r.depth_m for r in rows]), hold_s=np.zeros(72),
        sounded=np.concatenate([r.sounded for r in rows]))
    _, held = holdout_indices(batch)
    assert Counter(batch.vacuum_kpa[held].tolist()) == {-20.0: 12, -80.0: 12}
    for level in (-20.0, -80.0):
        mine = held[batch.vacuum_kpa[held] == level]
        assert Counter(np.round(batch.depth_m[mine], 3).tolist()) == {0.02: 4, 0.03: 4, 0.04: 4}
