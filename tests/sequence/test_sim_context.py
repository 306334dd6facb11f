"""On the simulated rig where the finger state carries through a sequence, a sequence model
trained on sequence-mode plans (the spec's `mode: sequence`) beats the per-note model
(own-world suite: pianobot's World makes the data; reported apart from the independent truth)."""

from __future__ import annotations

import numpy as np
import pytest

from pianobot.analysis.sequence.collect import random_sequences
from pianobot.analysis.sequence.evaluate import cross_validate_sequence
from pianobot.analysis.sequence.strokes import stroke_sequences
from tests.sequence.sim_world import context_world_trials


@pytest.mark.slow
def test_sequence_model_beats_the_per_note_model_on_held_out_sequences() -> None:
    trials = context_world_trials(36)
    assert trials["status"].eq("ok").mean() > 0.9
    cv = cross_validate_sequence(stroke_sequences(trials), ks=(2,), per_note=("gp",), folds=4, workers=1)
    rows = cv.set_index("model")
    per_note = rows.loc["per-note gp", "on_velocity_rmse"]
    context = rows.loc["sequence k=2", "on_velocity_rmse"]
    assert context < 0.85 * per_note, cv  # measured: 5.1 against 7.2 MIDI (0.71x)
    # Timing: the previous stroke's hold and release set when this note sounds (measured 0.25x).
    assert rows.loc["sequence k=2", "ioi_rmse_s"] < 0.5 * rows.loc["per-note gp", "ioi_rmse_s"], cv


def test_sequence_plan_draws_notes_and_parameters_per_stroke() -> None:
    plan = random_sequences(5, 12, notes=[60, 62, 64], ranges={"down_velocity_mps": (0.01, 0.05)},
                            fixed={"vacuum_kpa": -40.0, "depth_m": 0.03, "acceleration_mps2": 1.0,
                                   "distance_m": 0.01, "hold_s": 0.1}, seed=7)
    assert len(plan) == 60 and plan["sequence_id"].nunique() == 5
    assert list(plan["sequence_order"][:12]) == list(range(12))
    assert set(plan["note"]) <= {60, 62, 64} and plan["note"].nunique() == 3
    assert plan["down_velocity_mps"].between(0.01, 0.05).all() and plan["down_velocity_mps"].nunique() == 60
    np.testing.assert_array_equal(plan["up_velocity_mps"], plan["down_velocity_mps"])
    again = random_sequences(5, 12, notes=[60, 62, 64], ranges={"down_velocity_mps": (0.01, 0.05)},
                             fixed={"vacuum_kpa": -40.0, "depth_m": 0.03, "acceleration_mps2": 1.0,
                                    "distance_m": 0.01, "hold_s": 0.1}, seed=7)
    assert plan.equals(again)
    with pytest.raises(ValueError, match="neither drawn nor fixed"):
        random_sequences(1, 2, notes=[60], ranges={"down_velocity_mps": (0.01, 0.05)}, fixed={})
