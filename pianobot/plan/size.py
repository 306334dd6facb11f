"""How big a plan is, known before any of it is built: the trial count and its lab time.

A grid's size is the product of its level counts, known exactly from the spec; a typo such as
`num: 1000` on four parameters asks for 10¹² keystrokes. `check_size` refuses a plan above
`max_trials` before anything is allocated, and says how many trials and how much lab time
were asked for, estimated from a sample of the plan's own points.
"""

from __future__ import annotations

import math

import numpy as np

from pianobot.durations import format_long_duration
from pianobot.errors import InputError
from pianobot.plan.labtime import move_durations_s
from pianobot.plan.trial import FloatArray
from pianobot.spec import (
    PARAMETER_NAMES,
    PARAMETERS,
    ExperimentSpec,
    GridSweep,
    Linspace,
    Range,
    RigSpec,
    clean_value,
    default_value,
)
from pianobot.spec.parameters import missing_value

# About 5 days of non-stop keystrokes on the real rig at ~2 s each (the study's grid is 2,025);
# a plan this size takes ~110 MB in memory. `pianobot sweep --max-trials N` raises it.
DEFAULT_MAX_TRIALS = 200_000
_ESTIMATE_POINTS = 4096


def count_trials(spec: ExperimentSpec) -> int:
    """The number of trials `spec` plans (exact, as a Python int: it may be astronomically big)."""
    sweep = spec.sweep
    if isinstance(sweep, GridSweep):
        points = math.prod(
            value.num if isinstance(value, Linspace) else len(value)
            for _, value in sweep.params.items()
        )
    else:
        points = sweep.samples
    return points * sweep.repeats


def check_size(spec: ExperimentSpec, rig: RigSpec | None = None, *,
               max_trials: int = DEFAULT_MAX_TRIALS) -> int:
    """The trial count of `spec`; InputError (count and lab time) when it is above `max_trials`."""
    n = count_trials(spec)
    if n <= max_trials:
        return n
    label = str(spec.source_path) if spec.source_path else spec.name
    estimate = estimated_lab_time_s(spec, rig, n)
    raise InputError(
        f"plans {n:,} trials (≈ {format_long_duration(estimate)} of lab time), more than the limit of "
        f"{max_trials:,} trials per spec; narrow the sweep or split it, or raise the limit with "
        "--max-trials",
        f"{label}: sweep",
    )


def estimated_lab_time_s(spec: ExperimentSpec, rig: RigSpec | None, n_trials: int) -> float:
    """Lab time of `n_trials` presses like a random sample of the plan's points, plus pauses.

    Vacuum settling is counted once per vacuum level (the best order: blocked); key changes are
    left out. So this is a lower bound of what the run would take.
    """
    rig = rig if rig is not None else RigSpec()
    rng = np.random.default_rng(0)
    c = _sampled_columns(spec, rng, _ESTIMATE_POINTS)
    travel_m = c["distance_m"] + c["depth_m"]
    per_press_s = float(np.mean(
        move_durations_s(travel_m, c["down_velocity_mps"], c["acceleration_mps2"])
        + c["hold_s"]
        + move_durations_s(travel_m, c["up_velocity_mps"], c["acceleration_mps2"])
    ))
    vacuum_levels = len(np.unique(np.round(c["vacuum_kpa"], 6)))
    settle = rig.settle_s
    return (n_trials * (per_press_s + settle.between_presses_s)
            + vacuum_levels * settle.after_vacuum_change_s)


def _sampled_columns(spec: ExperimentSpec, rng: np.random.Generator, k: int) -> dict[str, FloatArray]:
    """`k` points drawn uniformly from the sweep (its levels, ranges or choices)."""
    sweep = spec.sweep
    held = {name: float(value) for name, value in sweep.fixed.items()}
    varied = dict(sweep.params.items())
    columns: dict[str, FloatArray] = {}
    for name in PARAMETER_NAMES:
        value = varied.get(name)
        if isinstance(value, Linspace):
            columns[name] = value.start + (value.stop - value.start) * (
                rng.integers(0, value.num, k) / max(1, value.num - 1))
        elif isinstance(value, Range):
            columns[name] = rng.uniform(value.low, value.high, k)
        elif isinstance(value, list):
            levels = np.array([clean_value(v) for v in value], dtype=np.float64)
            columns[name] = levels[rng.integers(0, len(levels), k)]
        elif name in held:
            columns[name] = np.full(k, held[name])
        elif (default := default_value(name, spec)) is not None:
            columns[name] = np.full(k, default)
    for name in PARAMETERS:  # what is left follows another parameter (up ← down), else unknown
        if name not in columns:
            followed = missing_value(name, columns)
            columns[name] = np.full(k, np.nan) if followed is None else np.array(followed, dtype=np.float64)
    return columns
