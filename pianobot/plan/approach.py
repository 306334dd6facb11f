"""The spec's `approach:` option applied to a plan: each trial's fast approach and retract.

`approach: fast` turns every press that allows it into a two-segment press (the run-up at
travel speed, then the spec's own move, exactly as it would have met the key; back up at travel
speed after lift-off), planned with the rig file's `approach:` settings by
`physics.approach.plan_fast_moves`. Trials that allow no exact shortcut (the arm would still
be accelerating at contact, or the run-up is too short to save time) keep the spec's moves.
The parameters, and so the keystrokes, are the same either way; only the commanded motion and
the lab time change.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

from pianobot.physics.approach import ApproachSettings, plan_fast_moves
from pianobot.plan.trial import Trial, trial_columns
from pianobot.spec import ExperimentSpec, RigSpec
from pianobot.spec.parameters import PRESS_PARAMETERS


def approach_settings(rig: RigSpec) -> ApproachSettings:
    """The rig file's `approach:` section as the physics layer's settings."""
    a = rig.approach
    return ApproachSettings(velocity_mps=a.velocity_mps, acceleration_mps2=a.acceleration_mps2,
                            clearance_m=a.clearance_m, settle_s=a.settle_s)


def with_fast_approach(trials: Sequence[Trial], rig: RigSpec | None = None) -> list[Trial]:
    """Every trial with its fast approach and retract planned (0 where none is exact)."""
    settings = approach_settings(rig if rig is not None else RigSpec())
    c = trial_columns(trials, PRESS_PARAMETERS)
    moves = plan_fast_moves(c["distance_m"], c["depth_m"], c["down_velocity_mps"],
                            c["up_velocity_mps"], c["acceleration_mps2"], settings)
    return [
        replace(t, approach_m=approach, retract_m=retract,
                travel_velocity_mps=settings.velocity_mps,
                travel_acceleration_mps2=settings.acceleration_mps2)
        for t, approach, retract in zip(trials, moves.approach_m.tolist(),
                                        moves.retract_m.tolist(), strict=True)
    ]


def as_specified(trials: Sequence[Trial]) -> list[Trial]:
    """Every trial with the spec's two moves only (no fast approach or retract)."""
    return [t if not (t.approach_m or t.retract_m) else replace(t, approach_m=0.0, retract_m=0.0)
            for t in trials]


def apply_approach(spec: ExperimentSpec, trials: Sequence[Trial], rig: RigSpec | None = None) -> list[Trial]:
    """The trials as the spec's `approach:` option commands them on `rig`."""
    if spec.approach == "fast":
        return with_fast_approach(trials, rig)
    return as_specified(trials)
