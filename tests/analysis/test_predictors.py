"""The physics predictor satisfies the protocol, and the contract's one inversion inverts it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pianobot.analysis.learn.files import load_predictor
from pianobot.analysis.learn.physical import PhysicsPredictor
from pianobot.analysis.learn.predictors import (
    OUTPUT_COLUMNS,
    LoudnessCurve,
    StrokePredictor,
)
from pianobot.errors import InputError
from pianobot.physics.model import KeystrokeModel, save_model


def test_physics_predictor_forward_and_inverse(tmp_path: Path) -> None:
    path = save_model(KeystrokeModel.study(), tmp_path / "m.json")
    pred = load_predictor(path)
    assert isinstance(pred, PhysicsPredictor) and isinstance(pred, StrokePredictor)
    fixed = {"vacuum_kpa": -60.0, "acceleration_mps2": 1.0, "depth_m": 0.03, "distance_m": 0.05}
    out = pred.predict(pd.DataFrame({"down_velocity_mps": [0.02, 0.06], **fixed}))
    assert list(out.columns) == list(OUTPUT_COLUMNS)
    assert out["on_velocity"].iloc[1] > out["on_velocity"].iloc[0]
    assert (out["lead_s"] > 0).all()
    curve = LoudnessCurve.tabulate(pred, np.geomspace(0.005, 0.08, 60), **fixed)
    lo, hi = curve.velocity_range
    targets = np.linspace(lo + 0.5, hi - 0.5, 4)
    speeds = curve.inverse(targets, strict=True)
    back = pred.predict(pd.DataFrame({"down_velocity_mps": speeds, **fixed}))["on_velocity"].to_numpy()
    assert np.max(np.abs(back - targets)) <= 1.0


def test_missing_speed_column_is_input_error() -> None:
    with pytest.raises(InputError):
        PhysicsPredictor.published().predict(pd.DataFrame({"vacuum_kpa": [0.0]}))
