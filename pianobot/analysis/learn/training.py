"""Training the learned maps (press parameters → MIDI outcome): grouped CV, fitting, saving.

`run` is the `pianobot fit` command's entry; this module holds the work it calls.

Targets: the note-on velocity and the MIDI hold time of sounded keystrokes, the lead from motion
start to note-on (`t_on_s`), and the probability that a keystroke is silent. Cross-validation is
grouped (`GroupKFold`) by setting, so the repeats of one setting never sit on both sides of a
split — otherwise a model could score by remembering a setting's repeats.

A fitted `LearnedPredictor` is a `StrokePredictor` (`pianobot.analysis.learn.predictors`); it is
saved and loaded by `learn.files` (`save_predictor`, `load_predictor`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd
from sklearn.model_selection import GroupKFold

from pianobot.analysis.learn.models import fit_classifier, make_regressor, p_silent
from pianobot.analysis.learn.predictors import (
    INPUT_COLUMNS,
    OUTPUT_COLUMNS,
    FloatArray,
    complete_inputs,
)
from pianobot.analysis.plausibility import midi_outcome
from pianobot.errors import InputError
from pianobot.executor import IN_PROCESS, Executor
from pianobot.progress import NO_PROGRESS, Progress

REGRESSION_TARGETS = {"on_velocity": "on_velocity", "midi_hold_s": "midi_hold_s", "lead_s": "t_on_s"}


@dataclass(frozen=True)
class TrainingSet:
    """Trials prepared for learning: inputs that vary, targets, silent flags and CV groups."""

    inputs: tuple[str, ...]
    X: FloatArray  # (n, len(inputs))
    silent: npt.NDArray[np.bool_]
    targets: dict[str, FloatArray]  # NaN where the target is unknown (silent, not recorded)
    groups: npt.NDArray[np.int64]
    ranges: dict[str, tuple[float, float]]
    defaults: dict[str, float]  # value of each non-varying input

    @property
    def n(self) -> int:
        return len(self.silent)


def training_set(trials: pd.DataFrame) -> TrainingSet:
    """Select executed trials and the inputs that vary among them.

    Raises:
        InputError: no usable trials, or no sounded keystroke to learn on-velocity from.
    """
    if trials is None or trials.empty:
        raise InputError("the run has no trials", "fit")
    frame = trials
    if "status" in frame:
        frame = frame[frame["status"].isin(["ok", "silent"])]
    frame = frame.dropna(subset=["down_velocity_mps"])
    if frame.empty:
        raise InputError("the run has no executed trials (all failed or missing parameters)", "fit")
    on = frame["on_velocity"].astype(float) if "on_velocity" in frame else pd.Series(np.nan, index=frame.index)
    outcome = midi_outcome(frame)
    if outcome.any() and not outcome.all():
        # Runs with MIDI and a take without it (a mocap import) together: the take's keystrokes
        # have no outcome to learn from (they used to reach the learner as NaN inputs and crash it).
        frame, on = frame[outcome], on[outcome]
    full = complete_inputs(frame)
    silent = (frame["status"] == "silent").to_numpy() if "status" in frame else on.isna().to_numpy()
    silent = silent | on.isna().to_numpy()
    if silent.all():
        said_silent = "status" in frame and bool((frame["status"] == "silent").any())
        midi_recorded = "n_note_on" in frame and bool(frame["n_note_on"].notna().any())
        if not said_silent and not midi_recorded:
            raise InputError("no keystroke has a MIDI outcome (no on-velocity recorded: a take without MIDI?); "
                             "fit learns loudness, hold and silence from keystrokes with MIDI", "fit")
        raise InputError("every keystroke is silent: nothing to learn on-velocity from", "fit")
    varying = _distinct_varying(full)
    X = full[list(varying)].to_numpy(float)
    targets = {}
    for name, column in REGRESSION_TARGETS.items():
        values = frame[column].astype(float).to_numpy() if column in frame else np.full(len(frame), np.nan)
        targets[name] = np.where(silent, np.nan, values)
    # Repeats share every input value: one group per distinct setting.
    _, groups = np.unique(np.round(full[list(INPUT_COLUMNS)].to_numpy(float), 9), axis=0, return_inverse=True)
    ranges = {c: (float(full[c].min()), float(full[c].max())) for c in INPUT_COLUMNS}
    defaults = {c: float(full[c].median()) for c in INPUT_COLUMNS if c not in varying}
    return TrainingSet(varying, X, silent, targets, groups.astype(np.int64).ravel(), ranges, defaults)


def _distinct_varying(full: pd.DataFrame) -> tuple[str, ...]:
    """Inputs that vary, without exact copies of an earlier one (the study moved up and down at
    one speed: a second, identical column adds a length scale to fit and nothing to learn)."""
    varying: list[str] = []
    for c in INPUT_COLUMNS:
        column = full[c].round(9)
        if column.nunique() <= 1 and c != "down_velocity_mps":
            continue
        if any(column.equals(full[v].round(9)) for v in varying):
            continue
        varying.append(c)
    if "down_velocity_mps" not in varying:
        varying.insert(0, "down_velocity_mps")
    return tuple(varying)


class LearnedPredictor:
    """Regressors for on-velocity, hold and lead plus a silent classifier (a `StrokePredictor`)."""

    def __init__(self, kind: str, seed: int = 0) -> None:
        self.kind = kind
        self.seed = seed

    def fit(self, data: TrainingSet, warm: LearnedPredictor | None = None) -> LearnedPredictor:
        """Fit every target on the sounded keystrokes and the classifier on all keystrokes.

        `warm`: a predictor of the same kind fitted before (e.g. on all the data) whose
        hyperparameters start this fit's optimiser — cross-validation folds converge in a few
        steps instead of searching from scratch. Only a fit on the same inputs starts one (a
        warm-up's hold map sees the arm's hold besides what its loudness map saw).
        """
        if warm is not None and tuple(getattr(warm, "inputs_", ())) != tuple(data.inputs):
            warm = None
        self.inputs_ = data.inputs
        self.ranges_ = data.ranges
        self.defaults_ = data.defaults
        self.regressors_: dict[str, Any] = {}
        for name, y in data.targets.items():
            rows = np.isfinite(y)
            if rows.sum() >= 3:
                start = None if warm is None else warm.regressors_.get(name)
                self.regressors_[name] = make_regressor(self.kind, data.inputs, self.seed, warm=start).fit(
                    data.X[rows], y[rows])
        if "on_velocity" not in self.regressors_:
            raise InputError("fewer than 3 sounded keystrokes: cannot fit on-velocity", "fit")
        self.classifier_ = fit_classifier(self.kind, data.inputs, data.X, data.silent, self.seed)
        return self

    def _matrix(self, frame: pd.DataFrame) -> FloatArray:
        full = complete_inputs(frame)
        return full[list(self.inputs_)].to_numpy(float)

    def predict(self, frame: pd.DataFrame) -> pd.DataFrame:
        """Outcome per row (see `StrokePredictor.predict`)."""
        X = self._matrix(frame)
        out = pd.DataFrame(index=frame.index)
        out["on_velocity"] = np.clip(self.regressors_["on_velocity"].predict(X), 1.0, 127.0)
        out["p_silent"] = np.clip(p_silent(self.classifier_, X), 0.0, 1.0)
        for name in ("lead_s", "midi_hold_s"):
            model = self.regressors_.get(name)
            out[name] = model.predict(X) if model is not None else np.nan
        return out[list(OUTPUT_COLUMNS)]


def _scores(y: FloatArray, pred: FloatArray) -> dict[str, float]:
    err = pred - y
    ss_tot = float(np.sum((y - y.mean()) ** 2))
    return {
        "rmse": float(np.sqrt(np.mean(err**2))),
        "mae": float(np.mean(np.abs(err))),
        "r2": 1.0 - float(np.sum(err**2)) / ss_tot if ss_tot > 0 else float("nan"),
    }


def cross_validate(data: TrainingSet, kinds: Sequence[str], *, folds: int = 5, seed: int = 0,
                   physics: Any | None = None) -> pd.DataFrame:
    """Grouped K-fold CV table: one row per model kind (plus the `mean` baseline).

    Columns: model, rmse, mae, r2 (on-velocity of sounded keystrokes), hold_rmse_s,
    silent_accuracy, latency_ms (median time to predict one stroke), fit_s (wall time of
    fitting on all the data), n_trials, folds. `physics` (a StrokePredictor) is evaluated
    without refitting: it was identified elsewhere.
    """
    return cross_validate_models(data, kinds, folds=folds, seed=seed, physics=physics)[0]


#: The folds run through an executor only when their estimated serial time (the full fits' time
#: times the number of folds) pays for starting worker processes (`executor.MIN_PARALLEL_WORK_S`).
FoldExecutor = Callable[[float], AbstractContextManager[Executor]]


def _in_process(work_s: float) -> AbstractContextManager[Executor]:
    return nullcontext(IN_PROCESS)


def cross_validate_models(data: TrainingSet, kinds: Sequence[str], *, folds: int = 5, seed: int = 0,
                          physics: Any | None = None, progress: Progress = NO_PROGRESS,
                          executor: FoldExecutor = _in_process,
                          ) -> tuple[pd.DataFrame, dict[str, LearnedPredictor]]:
    """`cross_validate` plus each learned kind fitted on all the data (ready to save).

    Each kind is first fitted on all the data, here; its hyperparameters warm-start every fold.
    The folds of every kind are independent pieces: they run through `executor(work_s)` (given
    the estimated serial seconds, it opens the executor to use: `pianobot.executor`'s local
    cluster or scheduler, or this process), each seeded alike, so the table is the same wherever
    they ran. Progress counts fits: per model kind one on all the data plus one per fold.
    """
    n_groups = int(np.unique(data.groups).size)
    k = max(2, min(folds, n_groups))
    splits = list(GroupKFold(n_splits=k).split(data.X, groups=data.groups))
    frame = pd.DataFrame(data.X, columns=list(data.inputs))
    learned = ["mean", *[kk for kk in kinds if kk not in ("physics", "mean")]]
    full: dict[str, LearnedPredictor] = {}
    fit_s: dict[str, float] = {}
    with progress.task("cross-validation", total=len(learned) * (k + 1)) as task:
        for kind in learned:
            task.update(note=f"{kind}: fit on all {data.n} keystrokes")
            t0 = time.perf_counter()
            full[kind] = LearnedPredictor(kind, seed).fit(data)
            fit_s[kind] = time.perf_counter() - t0
            task.advance()

        def fold(piece: tuple[str, int]) -> pd.DataFrame | None:
            kind, number = piece
            train, test = splits[number]
            try:
                model = LearnedPredictor(kind, seed).fit(_subset(data, train), warm=full[kind])
            except InputError:
                return None  # a fold without enough sounded keystrokes predicts nothing
            return model.predict(frame.iloc[test])

        pieces = [(kind, number) for kind in learned for number in range(k)]
        predicted = {kind: np.full((3, data.n), np.nan) for kind in learned}
        with executor(k * sum(fit_s.values())) as ex:
            for (kind, number), out in zip(pieces, ex.imap(fold, pieces), strict=True):
                task.advance(note=f"{kind}: fold {number + 1} of {k}")
                if out is not None:
                    test = splits[number][1]
                    predicted[kind][:, test] = out[["on_velocity", "midi_hold_s", "p_silent"]].to_numpy(float).T
    rows = [_row(kind, data, predicted[kind][0], predicted[kind][1], predicted[kind][2], _latency(full[kind], frame),
                 k) | {"fit_s": fit_s[kind]} for kind in learned]
    if "physics" in kinds and physics is not None:
        inputs = frame.assign(**data.defaults)
        out = physics.predict(inputs)
        rows.append(_row("physics", data, out["on_velocity"].to_numpy(float), out["midi_hold_s"].to_numpy(float),
                         out["p_silent"].to_numpy(float), _latency(physics, inputs), 0) | {"fit_s": 0.0})
    return pd.DataFrame(rows), full


def _subset(data: TrainingSet, rows: npt.NDArray[np.intp]) -> TrainingSet:
    return TrainingSet(data.inputs, data.X[rows], data.silent[rows],
                       {k: v[rows] for k, v in data.targets.items()}, data.groups[rows],
                       data.ranges, data.defaults)


def _row(kind: str, data: TrainingSet, pv: FloatArray, ph: FloatArray, ps: FloatArray,
         latency_ms: float, folds: int) -> dict[str, Any]:
    y = data.targets["on_velocity"]
    ok = np.isfinite(y) & np.isfinite(pv)
    scores = _scores(y[ok], pv[ok]) if ok.sum() >= 2 else {"rmse": np.nan, "mae": np.nan, "r2": np.nan}
    h = data.targets["midi_hold_s"]
    okh = np.isfinite(h) & np.isfinite(ph)
    hold = float(np.sqrt(np.mean((ph[okh] - h[okh]) ** 2))) if okh.any() else float("nan")
    oks = np.isfinite(ps)
    acc = float(np.mean((ps[oks] >= 0.5) == data.silent[oks])) if oks.any() else float("nan")
    return {"model": kind, **scores, "hold_rmse_s": hold, "silent_accuracy": acc,
            "latency_ms": latency_ms, "n_trials": data.n, "folds": folds}


def _latency(model: Any, frame: pd.DataFrame, repeats: int = 5) -> float:
    """Median wall time of predicting a single stroke, in milliseconds."""
    one = frame.iloc[:1]
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        model.predict(one)
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))
