"""The sequence model on data from an independent truth (tests/sequence/seq_truth.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pianobot.analysis.sequence.context import features
from pianobot.analysis.sequence.evaluate import cross_validate_sequence
from pianobot.analysis.sequence.files import load_sequence_model, save_sequence_model
from pianobot.analysis.sequence.model import SequenceModel
from pianobot.analysis.sequence.strokes import STRETCH_STROKES, stroke_sequences
from pianobot.errors import InputError
from tests.sequence.seq_truth import make_trials


@pytest.fixture(scope="module")
def trials() -> pd.DataFrame:
    return make_trials(48, 8, seed=4)


def test_strokes_are_put_in_play_order_with_inter_onset_intervals(trials: pd.DataFrame) -> None:
    shuffled = trials.sample(frac=1.0, random_state=0)
    table = stroke_sequences(shuffled)
    frame = table.frame
    assert table.n_sequences == 48
    assert (frame.groupby("sequence")["order"].apply(lambda s: list(s) == sorted(s))).all()
    first = frame[frame["order"] == 0]
    assert first["ioi_s"].isna().all()  # nothing before the first stroke of a sequence
    ordered = trials.sort_values(["sequence_id", "sequence_order"])
    onset = (ordered["t_start_s"] + ordered["t_on_s"]).to_numpy()
    expected = onset[1:] - onset[:-1]
    same = ordered["sequence_id"].to_numpy()[1:] == ordered["sequence_id"].to_numpy()[:-1]
    got = frame["ioi_s"].to_numpy()[1:]
    ok = same & np.isfinite(expected)
    np.testing.assert_allclose(got[ok], expected[ok])


def test_a_run_without_sequence_ids_is_cut_into_stretches(trials: pd.DataFrame) -> None:
    table = stroke_sequences(trials.drop(columns=["sequence_id", "sequence_order"]))
    assert table.n_sequences == int(np.ceil(len(trials) / STRETCH_STROKES))
    assert table.frame["order"].max() == STRETCH_STROKES - 1


def test_context_never_reaches_across_sequences(trials: pd.DataFrame) -> None:
    table = stroke_sequences(trials)
    frame = table.frame
    n = table.n
    X = features(frame, table.controls, 2, np.zeros(n), np.ones(n))
    n_own = len(table.controls)
    lag1 = X[:, n_own + 2 :]
    lag1_first = lag1[frame["order"].to_numpy() == 0]
    assert np.isnan(lag1_first).all()
    lag2 = X[:, n_own + 2 + (X.shape[1] - n_own - 2) // 2 :]
    assert np.isnan(lag2[frame["order"].to_numpy() == 1]).all()
    assert np.isfinite(lag1[frame["order"].to_numpy() == 1]).any()


def test_context_beats_the_per_note_model_on_held_out_sequences(trials: pd.DataFrame) -> None:
    table = stroke_sequences(trials)
    cv = cross_validate_sequence(table, ks=(0, 2), per_note=("gp",), folds=4, workers=1).set_index("model")
    per_note = cv.loc["per-note gp", "on_velocity_rmse"]
    alone = cv.loc["sequence k=0", "on_velocity_rmse"]
    context = cv.loc["sequence k=2", "on_velocity_rmse"]
    # The hidden per-sequence finger state spreads loudness by tens of MIDI steps; the last two
    # strokes' residuals reveal it.
    assert context < 0.75 * per_note, cv
    assert context < 0.75 * alone, cv
    assert cv.loc["sequence k=2", "n_sequences"] == 48


def test_predicting_the_next_stroke_agrees_with_predicting_it_in_its_sequence(trials: pd.DataFrame) -> None:
    table = stroke_sequences(trials)
    model = SequenceModel(2).fit(table)
    in_sequence = model.predict(table)
    frame = table.frame
    last = frame.index[(frame["sequence"] == 5) & (frame["order"] == 7)][0]
    history = frame[(frame["sequence"] == 5) & (frame["order"] < 7)]
    nxt = model.predict_next(history, frame.loc[[last]])
    for name in ("on_velocity", "lead_s", "p_silent"):
        assert nxt[name].iloc[0] == pytest.approx(in_sequence[name].iloc[last], rel=1e-9, abs=1e-9)
    # More speed, more loudness: the model predicts a louder stroke for a faster candidate.
    candidates = pd.concat([frame.loc[[last]]] * 2, ignore_index=True)
    candidates.loc[0, "down_velocity_mps"], candidates.loc[1, "down_velocity_mps"] = 0.015, 0.055
    louder = model.predict_next(history, candidates)["on_velocity"].to_numpy()
    assert louder[1] > louder[0] + 10


def test_model_files_round_trip_and_refuse_a_changed_estimator(trials: pd.DataFrame, tmp_path: Path) -> None:
    table = stroke_sequences(trials)
    model = SequenceModel(1).fit(table)
    path = save_sequence_model(model, tmp_path / "m" / "sequence.json", runs=["truth"])
    sidecar = json.loads(path.read_text())
    assert sidecar["schema"] == "pianobot.sequence-model/1" and sidecar["k"] == 1
    again = load_sequence_model(path)
    pd.testing.assert_frame_equal(again.predict(table), model.predict(table))
    path.with_suffix(".joblib").write_bytes(b"changed")
    with pytest.raises(InputError, match="sha256"):
        load_sequence_model(path)


def test_unfitted_model_and_hopeless_data_are_refused(trials: pd.DataFrame) -> None:
    with pytest.raises(RuntimeError, match="not fitted"):
        SequenceModel(1).predict(stroke_sequences(trials))
    with pytest.raises(InputError, match="silent"):
        stroke_sequences(trials.assign(on_velocity=np.nan, status="silent"))
    with pytest.raises(ValueError):
        SequenceModel(-1)


def test_the_chosen_context_weighs_loudness_and_timing_alike() -> None:
    from pianobot.analysis.sequence.fit import choose_k

    cv = pd.DataFrame({"model": ["per-note gp", "sequence k=0", "sequence k=1", "sequence k=2"],
                       "k": [None, 0, 1, 2], "on_velocity_rmse": [10.3, 9.4, 9.8, 9.85],
                       "ioi_rmse_s": [1.26, 1.11, 0.52, 0.52], "lead_rmse_s": [np.nan] * 4})
    assert choose_k(cv) == 1  # timing halves, loudness 4 % worse; k=2 is no better than k=1
    cv["ioi_rmse_s"] = [1.26, 1.11, 1.11, 1.12]
    assert choose_k(cv) == 0  # context helps nothing
