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


def test_loudness_curve_is_monotone_and_inverts_to_the_slowest_speed() -> None:
    """A silent start, a dip and a plateau: the inverse picks the slowest speed reaching a
    loudness, `fastest_within` the fastest, and only `strict` refuses what is out of reach."""
    speeds = np.array([0.01, 0.02, 0.03, 0.04, 0.05, 0.06])
    on = np.array([5.0, 10.0, 20.0, 18.0, 30.0, 40.0])
    p_silent = np.array([0.9, 0.1, 0.0, 0.0, 0.0, 0.0])  # the crawl is likely silent
    curve = LoudnessCurve.from_outcome(speeds, on, p_silent)
    np.testing.assert_array_equal(curve.velocity, [np.nan, 10.0, 20.0, 20.0, 30.0, 40.0])
    assert curve.velocity_range == (10.0, 40.0) and curve.sounds
    np.testing.assert_allclose(curve.inverse([10.0, 20.0, 25.0, 40.0]), [0.02, 0.03, 0.04, 0.06])
    np.testing.assert_allclose(curve.fastest_within([20.0], 0.0), [0.04])
    np.testing.assert_allclose(curve.inverse([2.0, 90.0]), [0.02, 0.06])  # nearest reachable
    assert np.isnan(curve.inverse([2.0, 90.0], strict=True)).all()
    np.testing.assert_allclose(curve.predict_velocity([0.035]), [20.0])
    silent = LoudnessCurve.from_outcome(speeds, on, np.ones(6))
    assert not silent.sounds and np.isnan(silent.inverse([20.0])).all()


def test_loudness_curve_of_a_predictor_matches_its_predictions() -> None:
    """`tabulate` asks the predictor with the fixed inputs; the curve holds what it answered."""
    pred = PhysicsPredictor.published()
    fixed = {"vacuum_kpa": -40.0, "acceleration_mps2": 1.0, "depth_m": 0.03, "distance_m": 0.05}
    speeds = np.array([0.02, 0.04, 0.06])
    curve = LoudnessCurve.tabulate(pred, speeds, **fixed)
    direct = pred.predict(pd.DataFrame({"down_velocity_mps": speeds, **fixed}))["on_velocity"].to_numpy()
    np.testing.assert_allclose(curve.velocity, np.maximum.accumulate(direct))
