"""Honest evaluation of the sequence model: cross-validation grouped by sequence.

Whole sequences are held out (`GroupKFold` on the sequence), so a model never sees a test
stroke's neighbours. On the same folds:

- `per-note gp` (and any other per-note kind of `pianobot fit`): the per-note model, fitted on
  the per-note inputs (`pianobot.analysis.learn.predictors.INPUT_COLUMNS`) that vary;
- `sequence k=0`: the sequence model's own learner without context (the stroke's own
  controls, including a log's sideways move): the difference to k ≥ 1 is the value of context;
- `sequence k=1…`: with the last k strokes;
- `rnn gru` (optional, PyTorch): the recurrent model (`rnn`), everything before in its state.

Scores: on-velocity RMSE/MAE of sounded strokes; RMSE of the inter-onset interval (previous
note-on → this note-on; the timing a sequence log records), of the lead (motion start →
note-on, where known) and of the MIDI hold; silent accuracy. Folds run on the executor.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd
from sklearn.model_selection import GroupKFold

from pianobot.analysis.learn.models import make_regressor
from pianobot.analysis.learn.predictors import INPUT_COLUMNS
from pianobot.analysis.sequence.model import MIN_TARGET_ROWS, SequenceModel
from pianobot.analysis.sequence.strokes import TARGETS, StrokeSequences
from pianobot.errors import InputError
from pianobot.executor import ExecutorSettings, open_executor
from pianobot.progress import NO_PROGRESS, Progress

FloatArray = npt.NDArray[np.float64]

DEFAULT_KS: tuple[int, ...] = (0, 1, 2, 3)
#: Targets the per-note baselines are scored on (the MIDI hold's baseline is `pianobot fit`'s table).
PER_NOTE_TARGETS: tuple[str, ...] = ("on_velocity", "ioi_s", "lead_s")
#: Measured serial cost of one fold task on a busy 2-core machine (for the executor's choice).
TASK_COST_S = 1.5


@dataclass(frozen=True)
class _Task:
    model: str  # "sequence" or a per-note kind
    k: int
    table: StrokeSequences
    train: npt.NDArray[np.intp]
    test: npt.NDArray[np.intp]
    seed: int


def _subset(table: StrokeSequences, rows: npt.NDArray[np.intp]) -> StrokeSequences:
    return StrokeSequences(table.frame.iloc[rows].reset_index(drop=True), table.controls)


def _run(task: _Task) -> tuple[npt.NDArray[np.intp], pd.DataFrame]:
    train, test = _subset(task.table, task.train), _subset(task.table, task.test)
    if task.model == "sequence":
        return task.test, SequenceModel(task.k, task.seed).fit(train).predict(test)
    if task.model == "rnn":
        from pianobot.analysis.sequence.rnn import RnnSequenceModel  # torch: an optional extra

        return task.test, RnnSequenceModel(task.seed).fit(train).predict(test)
    return task.test, _per_note(task.model, train, test, task.seed)


def per_note_inputs(table: StrokeSequences) -> tuple[str, ...]:
    """The per-note model's inputs: `INPUT_COLUMNS` that vary in this table."""
    return tuple(c for c in INPUT_COLUMNS if c in table.controls)


def _per_note(kind: str, train: StrokeSequences, test: StrokeSequences, seed: int) -> pd.DataFrame:
    inputs = per_note_inputs(train)
    X, Xt = (t.frame[list(inputs)].to_numpy(float) for t in (train, test))
    out = pd.DataFrame(np.nan, index=range(test.n), columns=list(TARGETS))
    for name in PER_NOTE_TARGETS:
        y = train.frame[name].to_numpy(float)
        rows = np.isfinite(y)
        out[name] = (make_regressor(kind, inputs, seed).fit(X[rows], y[rows]).predict(Xt)
                     if rows.sum() >= MIN_TARGET_ROWS else np.nan)
    # The per-note silent rate: the training frequency (its classifier is scored by `pianobot fit`).
    out["p_silent"] = float(train.frame["silent"].mean())
    return out


def cross_validate_sequence(
    table: StrokeSequences, *, ks: Sequence[int] = DEFAULT_KS, per_note: Sequence[str] = ("gp",),
    folds: int = 5, seed: int = 0, workers: int | None = None, progress: Progress = NO_PROGRESS,
    rnn: bool = False,
) -> pd.DataFrame:
    """Grouped-CV table: one row per model (per-note kinds, then the sequence model per k, then
    with `rnn` the recurrent model, row "rnn gru").

    Columns: model, k, on_velocity_rmse, on_velocity_mae, ioi_rmse_s, lead_rmse_s,
    hold_rmse_s, silent_accuracy, n_strokes, n_sequences, folds.

    Raises:
        InputError: fewer than 2 sequences (nothing to hold out).
    """
    groups = table.groups
    n_groups = int(np.unique(groups).size)
    if n_groups < 2:
        raise InputError("the runs hold fewer than 2 sequences: grouped cross-validation needs at least 2",
                         "fit --model sequence")
    k_folds = max(2, min(folds, n_groups))
    splits = list(GroupKFold(n_splits=k_folds).split(np.zeros(table.n), groups=groups))
    models = [(kind, 0) for kind in per_note] + [("sequence", int(k)) for k in ks] + ([("rnn", 0)] if rnn else [])
    if rnn:
        from pianobot.analysis.sequence.rnn import require_torch

        require_torch()  # before any fold runs: one line on how to install it
    tasks = [_Task(m, k, table, tr, te, seed) for m, k in models for tr, te in splits]
    settings = ExecutorSettings.resolve(workers=workers, scheduler=None)
    with open_executor(settings, work_s=TASK_COST_S * len(tasks)) as ex:
        results = ex.map(_run, tasks, progress=progress, description="sequence cross-validation")
    rows = []
    for i, (model, k) in enumerate(models):
        pred = pd.DataFrame(np.nan, index=range(table.n), columns=[*TARGETS, "p_silent"])
        for test, out in results[i * k_folds : (i + 1) * k_folds]:
            pred.iloc[test] = out[list(pred.columns)].to_numpy(float)
        name = f"sequence k={k}" if model == "sequence" else "rnn gru" if model == "rnn" else f"per-note {model}"
        rows.append({"model": name, "k": k if model == "sequence" else None,
                     **_scores(table.frame, pred), "n_strokes": table.n,
                     "n_sequences": table.n_sequences, "folds": k_folds})
    return pd.DataFrame(rows)


def _rmse(y: FloatArray, p: FloatArray) -> float:
    ok = np.isfinite(y) & np.isfinite(p)
    return float(np.sqrt(np.mean((p[ok] - y[ok]) ** 2))) if ok.sum() >= 2 else float("nan")


def _scores(frame: pd.DataFrame, pred: pd.DataFrame) -> dict[str, Any]:
    y, p = frame["on_velocity"].to_numpy(float), pred["on_velocity"].to_numpy(float)
    ok = np.isfinite(y) & np.isfinite(p)
    silent = frame["silent"].to_numpy(bool)
    ps = pred["p_silent"].to_numpy(float)
    return {
        "on_velocity_rmse": _rmse(y, p),
        "on_velocity_mae": float(np.mean(np.abs(p[ok] - y[ok]))) if ok.any() else float("nan"),
        "ioi_rmse_s": _rmse(frame["ioi_s"].to_numpy(float), pred["ioi_s"].to_numpy(float)),
        "lead_rmse_s": _rmse(frame["lead_s"].to_numpy(float), pred["lead_s"].to_numpy(float)),
        "hold_rmse_s": _rmse(frame["midi_hold_s"].to_numpy(float), pred["midi_hold_s"].to_numpy(float)),
        "silent_accuracy": float(np.mean((ps >= 0.5) == silent)) if np.isfinite(ps).all() else float("nan"),
    }
