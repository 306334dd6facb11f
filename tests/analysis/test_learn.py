"""Learned predictors: grouped CV beats the mean, inverse round-trips, files load back."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from _synthetic_runs import sounded_trials

from pianobot.analysis.learn.files import load_predictor, save_predictor
from pianobot.analysis.learn.predictors import LoudnessCurve, StrokePredictor, speed_grid
from pianobot.analysis.learn.training import (
    LearnedPredictor,
    cross_validate,
    training_set,
)
from pianobot.errors import InputError


def test_cv_table_best_model_beats_mean() -> None:
    data = training_set(sounded_trials(0))
    table = cross_validate(data, ["poly", "spline"], folds=4).set_index("model")
    assert {"rmse", "mae", "r2", "silent_accuracy", "latency_ms"} <= set(table.columns)
    assert table.loc["mean", "r2"] < 0.1
    assert max(table.loc["poly", "r2"], table.loc["spline", "r2"]) > 0.9
    assert table.loc["poly", "silent_accuracy"] > 0.8


def test_groups_keep_repeats_together() -> None:
    data = training_set(sounded_trials(1, n_repeats=3))
    assert np.unique(data.groups).size == data.n // 3


@pytest.mark.parametrize("kind", ["poly", "gp"])
def test_inverse_round_trips_within_one_midi_unit(kind: str, tmp_path: Path) -> None:
    model = LearnedPredictor(kind).fit(training_set(sounded_trials(2)))
    assert isinstance(model, StrokePredictor)
    fixed = {"vacuum_kpa": -40.0, "acceleration_mps2": 0.5, "depth_m": 0.03, "distance_m": 0.05}
    trained = model.ranges_["down_velocity_mps"]
    curve = LoudnessCurve.tabulate(model, speed_grid(trained[0], min(trained[1], 0.08)), **fixed)
    lo, hi = curve.velocity_range
    targets = np.linspace(lo + 0.5, hi - 0.5, 9)
    speeds = curve.inverse(targets, strict=True)
    assert np.isfinite(speeds).all()
    back = model.predict(pd.DataFrame({"down_velocity_mps": speeds, **fixed}))["on_velocity"]
    assert np.max(np.abs(back.to_numpy() - targets)) <= 1.0
    assert np.isnan(curve.inverse([200.0], strict=True)).all()
    path = save_predictor(model, tmp_path / "p.json")
    loaded = load_predictor(path)
    again = loaded.predict(pd.DataFrame({"down_velocity_mps": speeds, **fixed}))["on_velocity"]
    np.testing.assert_allclose(again.to_numpy(), back.to_numpy())


def test_keystrokes_of_a_take_without_midi_are_left_out_not_learnt_as_nan() -> None:
    # `fit LOG TAKE`: the take's keystrokes have no MIDI and no acceleration or depth; they used
    # to reach scikit-learn as NaN inputs ("Input X contains NaN", a traceback).
    from pianobot.analysis.plausibility import fit_findings

    log = sounded_trials(4)
    take = pd.DataFrame({"trial_id": [f"take-{i}" for i in range(6)], "status": "ok",
                         "down_velocity_mps": np.linspace(0.01, 0.06, 6), "vacuum_kpa": -40.0,
                         "on_velocity": np.nan, "acceleration_mps2": np.nan, "depth_m": np.nan})
    both = pd.concat([log, take], ignore_index=True)
    data = training_set(both)
    assert data.n == training_set(log).n and np.isfinite(data.X).all()
    LearnedPredictor("poly").fit(data)
    texts = [f.text() for f in fit_findings(both, pd.DataFrame())]
    assert any("6 keystroke(s) without a MIDI outcome" in t for t in texts)
    assert not any("is silent" in t for t in texts)  # a take without MIDI is not a silent one


def test_all_silent_is_input_error() -> None:
    trials = sounded_trials(3).assign(status="silent", on_velocity=np.nan)
    with pytest.raises(InputError, match="silent"):
        training_set(trials)


def test_wrong_schema_and_tampered_file(tmp_path: Path) -> None:
    other = tmp_path / "other.json"
    other.write_text('{"schema": "something/9"}')
    with pytest.raises(InputError, match="schema"):
        load_predictor(other)
    model = LearnedPredictor("poly").fit(training_set(sounded_trials(4)))
    path = save_predictor(model, tmp_path / "p.json")
    path.with_suffix(".joblib").write_bytes(b"changed")
    with pytest.raises(InputError, match="sha256"):
        load_predictor(path)


def test_fit_on_study_soft_finger_logs(zhang2022: Path, data_dir: Path) -> None:
    from pianobot.analysis.learn.run import fit_runs
    from pianobot.io.importers import import_keystroke_log

    logs = sorted((zhang2022 / "data" / "soft" / "ctrl_midi").glob("*.txt"))
    ids = [import_keystroke_log(f, data_dir).run_id for f in logs]
    result = fit_runs(ids, data_dir, kinds=["gp", "poly"], out_dir=data_dir / "models")
    table, saved = result.cv, result.saved
    rows = table.set_index("model")
    assert rows.loc["mean", "r2"] < 0.05
    # Measured (405 keystrokes, 5 grouped folds): gp R² 0.967, poly 0.83, spline 0.88, mlp 0.95.
    assert rows.loc["gp", "r2"] > 0.9 and rows.loc["poly", "r2"] > 0.75
    assert rows.loc["gp", "silent_accuracy"] > 0.95
    model = load_predictor(saved["gp"])
    fixed = {"vacuum_kpa": -60.0, "acceleration_mps2": 0.5, "depth_m": 0.03, "distance_m": 0.05}
    trained = model.ranges_["down_velocity_mps"]  # a LearnedPredictor
    curve = LoudnessCurve.tabulate(model, speed_grid(trained[0], min(trained[1], 0.08)), **fixed)
    lo, hi = curve.velocity_range
    targets = np.linspace(lo + 0.5, hi - 0.5, 8)
    speeds = curve.inverse(targets, strict=True)
    back = model.predict(pd.DataFrame({"down_velocity_mps": speeds, **fixed}))["on_velocity"].to_numpy()
    assert np.nanmax(np.abs(back - targets)) <= 1.0


def test_the_physics_row_refuses_a_learned_predictor(data_dir: Path, tmp_path: Path) -> None:
    # A GP trained on these keystrokes, given as --physics-model, read as a perfect physics model.
    from _synthetic_runs import write_run

    from pianobot.analysis.learn.run import fit_runs

    run = write_run(data_dir, sounded_trials(5), None)
    saved = fit_runs([run], data_dir, kinds=["poly"], out_dir=tmp_path).saved["poly"]
    with pytest.raises(InputError, match="learned predictor, not a keystroke model"):
        fit_runs([run], data_dir, kinds=["physics"], out_dir=None, physics_model=saved)
    with pytest.raises(InputError, match="sequence, rnn"):
        fit_runs([run], data_dir, kinds=["foo"], out_dir=None)
