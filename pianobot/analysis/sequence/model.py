"""The windowed sequence model: this stroke's outcome from its controls and the last k strokes.

Two stages, both gradient-boosted trees (scikit-learn `HistGradientBoosting*`: fast on a few
thousand strokes, NaN-aware, no scaling needed):

1. the context-free model (k = 0): on-velocity, hold, lead, inter-onset interval and silence
   from the stroke's own controls;
2. with k ≥ 1, the same targets from the own controls, the context-free on-velocity, and the
   last k strokes' controls, outcomes and residuals (`context`). The residuals of training
   strokes come from context-free models fitted without the stroke's sequence (cross-fitting),
   so they look like the residuals the model will meet on new sequences.

`SequenceModel.predict(table)` predicts each stroke given its real predecessors (what the
robot observed); `predict_next(history, candidates)` predicts one new stroke's outcome for
many candidate controls after a given history — what `play` asks when it plans a note.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd
from sklearn.ensemble import HistGradientBoostingClassifier, HistGradientBoostingRegressor
from sklearn.model_selection import GroupKFold
from threadpoolctl import threadpool_limits

from pianobot.analysis.sequence.context import OUTCOMES, feature_names, features
from pianobot.analysis.sequence.strokes import TARGETS, StrokeSequences
from pianobot.errors import InputError
from pianobot.spec.parameters import PARAMETERS

FloatArray = npt.NDArray[np.float64]

#: Fewest known values of a target to learn it from.
MIN_TARGET_ROWS = 20
#: Folds of the cross-fitting that gives training strokes out-of-sequence residuals.
RESIDUAL_FOLDS = 3
#: Training contexts kept with a fitted model: what "a typical context" is when a plan asks
#: what its own context changes (`planned_effect`).
REFERENCE_CONTEXTS = 48


def _regressor(seed: int) -> HistGradientBoostingRegressor:
    # Shallow trees, a slow learning rate and an L2 penalty: a few hundred to a few thousand
    # noisy strokes. No early stopping, so a fit depends only on its data and seed.
    return HistGradientBoostingRegressor(max_iter=100, learning_rate=0.1, max_leaf_nodes=15,
                                         min_samples_leaf=15, l2_regularization=1.0,
                                         early_stopping=False, random_state=seed)


class _Constant:
    """P(silent) = training frequency, when a training set holds one class only."""

    def __init__(self, p: float) -> None:
        self.p = p

    def predict_proba(self, X: FloatArray) -> FloatArray:
        return np.column_stack([np.full(len(X), 1.0 - self.p), np.full(len(X), self.p)])


class _Stage:
    """One regressor per learnable target plus the silent classifier, on one feature matrix."""

    def __init__(self, seed: int) -> None:
        self.seed = seed
        self.regressors: dict[str, Any] = {}
        self.classifier: Any = None

    def fit(self, X: FloatArray, frame: pd.DataFrame, targets: tuple[str, ...] = TARGETS) -> _Stage:
        # A feature with no value at all (a context nobody had in a small training set) breaks
        # the trees' binning; held at 0 it is never split on.
        self.dead = np.isnan(X).all(axis=0) if len(X) else np.zeros(X.shape[1], bool)
        X = self._usable(X)
        for name in targets:
            y = frame[name].to_numpy(float)
            rows = np.isfinite(y)
            if rows.sum() >= MIN_TARGET_ROWS:
                self.regressors[name] = _regressor(self.seed).fit(X[rows], y[rows])
        silent = frame["silent"].to_numpy(bool)
        if targets != TARGETS:
            self.classifier = _Constant(float(silent.mean()))
        elif silent.sum() >= 3 and (~silent).sum() >= 3:
            self.classifier = HistGradientBoostingClassifier(
                max_iter=100, learning_rate=0.05, max_leaf_nodes=7, min_samples_leaf=15,
                l2_regularization=1.0, early_stopping=False, random_state=self.seed).fit(X, silent)
        else:
            self.classifier = _Constant(float(silent.mean()))
        return self

    def _usable(self, X: FloatArray) -> FloatArray:
        dead = getattr(self, "dead", None)
        if dead is None or not dead.any():
            return X
        X = X.copy()
        X[:, dead] = 0.0
        return X

    def predict(self, X: FloatArray) -> pd.DataFrame:
        X = self._usable(X)
        out = pd.DataFrame({name: (self.regressors[name].predict(X) if name in self.regressors
                                   else np.full(len(X), np.nan)) for name in TARGETS})
        out["on_velocity"] = np.clip(out["on_velocity"], 1.0, 127.0)
        out["p_silent"] = np.asarray(self.classifier.predict_proba(X), float)[:, -1]
        return out


class SequenceModel:
    """Forward model of a stroke given the last `k` strokes of its sequence (k = 0: alone)."""

    def __init__(self, k: int = 2, seed: int = 0) -> None:
        if k < 0:
            raise ValueError(f"k must be >= 0, got {k}")
        self.k = k
        self.seed = seed

    def fit(self, table: StrokeSequences) -> SequenceModel:
        """Fit both stages on the strokes of `table`.

        Raises:
            InputError: fewer than `MIN_TARGET_ROWS` sounded strokes.
        """
        # One thread: on a few thousand strokes OpenMP threads gain little, and on a shared
        # machine (or inside executor workers, one per core) they spin against each other.
        with threadpool_limits(1):
            return self._fit(table)

    def _fit(self, table: StrokeSequences) -> SequenceModel:
        frame = table.frame
        if int(np.isfinite(frame["on_velocity"]).sum()) < MIN_TARGET_ROWS:
            raise InputError(f"fewer than {MIN_TARGET_ROWS} sounded strokes: cannot fit a sequence model",
                             "fit --model sequence")
        self.controls_ = table.controls
        self.feature_names_ = feature_names(self.controls_, self.k)
        own = frame[list(self.controls_)].to_numpy(float)
        self.base_ = _Stage(self.seed).fit(own, frame)
        self.ranges_ = {c: (float(frame[c].min()), float(frame[c].max())) for c in self.controls_}
        self.n_strokes_ = table.n
        self.n_sequences_ = table.n_sequences
        if self.k == 0:
            return self
        base_on = self._cross_fitted_base(own, table)
        X = features(frame, self.controls_, self.k, base_on, frame["on_velocity"].to_numpy(float) - base_on)
        self.stage_ = _Stage(self.seed).fit(X, frame)
        followers = np.flatnonzero(frame["order"].to_numpy() > 0)
        if followers.size:
            rng = np.random.default_rng(self.seed)
            pick = rng.choice(followers, size=min(REFERENCE_CONTEXTS, followers.size), replace=False)
            self.contexts_ = X[np.sort(pick), len(self.controls_) + 1:]
        return self

    def _cross_fitted_base(self, own: FloatArray, table: StrokeSequences) -> FloatArray:
        """Context-free on-velocity of each training stroke from a model that never saw its sequence."""
        groups = table.groups
        folds = min(RESIDUAL_FOLDS, int(np.unique(groups).size))
        if folds < 2:
            return np.asarray(self.base_.predict(own)["on_velocity"], float)
        out = np.full(table.n, np.nan)
        for train, test in GroupKFold(n_splits=folds).split(own, groups=groups):
            stage = _Stage(self.seed).fit(own[train], table.frame.iloc[train], ("on_velocity",))
            out[test] = stage.predict(own[test])["on_velocity"]
        # A fold too small to learn from: the model of every stroke stands in.
        missing = ~np.isfinite(out)
        if missing.any():
            out[missing] = np.asarray(self.base_.predict(own[missing])["on_velocity"], float)
        return out

    def _check(self) -> None:
        if not hasattr(self, "base_"):
            raise RuntimeError("SequenceModel is not fitted; call fit first")

    def predict(self, table: StrokeSequences) -> pd.DataFrame:
        """Each stroke's predicted outcome given its observed predecessors.

        Columns: `TARGETS` and `p_silent`, one row per stroke of `table` (same order).
        """
        self._check()
        frame = table.frame
        own = frame[list(self.controls_)].to_numpy(float)
        base = self.base_.predict(own)
        if self.k == 0:
            return base
        base_on = base["on_velocity"].to_numpy(float)
        X = features(frame, self.controls_, self.k, base_on, frame["on_velocity"].to_numpy(float) - base_on)
        return self.stage_.predict(X)

    def predict_next(self, history: pd.DataFrame, candidates: pd.DataFrame) -> pd.DataFrame:
        """Outcomes of one new stroke, for each candidate's controls, after `history`.

        `history`: the strokes played before it, oldest first (controls plus `on_velocity`,
        `silent`, `midi_hold_s`; observed or, when planning, predicted); `candidates`: one row
        per candidate control set. Controls a frame lacks take the model's training median.
        """
        self._check()
        cand = self._controls_of(candidates)
        own = cand[list(self.controls_)].to_numpy(float)
        base = self.base_.predict(own)
        if self.k == 0:
            return base
        past = self._controls_of(history.tail(self.k).reset_index(drop=True))
        for name in OUTCOMES:
            values = history[name].tail(self.k).to_numpy(float) if name in history else np.full(len(past), np.nan)
            past[name] = values
        # One sequence: the history, then a placeholder row for the new stroke (its lags are
        # what we need); each candidate then differs only in its own controls.
        rows = pd.concat([past, cand.iloc[:1]], ignore_index=True)
        rows["sequence"] = 0
        for name in OUTCOMES:
            rows.loc[len(past), name] = np.nan
        past_own = rows[list(self.controls_)].to_numpy(float)
        past_base = self.base_.predict(past_own)["on_velocity"].to_numpy(float)
        residual = rows["on_velocity"].to_numpy(float) - past_base
        lagged = features(rows, self.controls_, self.k, past_base, residual)[-1]
        X = np.tile(lagged, (len(cand), 1))
        n_own = len(self.controls_)
        X[:, :n_own] = own
        X[:, n_own] = base["on_velocity"].to_numpy(float)
        prev_note = float(past["note"].iloc[-1]) if len(past) else np.nan
        X[:, n_own + 1] = cand["note"].to_numpy(float) - prev_note
        return self.stage_.predict(X)

    def planned_effect(self, strokes: pd.DataFrame, reference: pd.DataFrame | None = None) -> pd.DataFrame:
        """What the context changes in each stroke of a plan: with context minus without.

        `strokes`: the strokes of one sequence in play order, controls only (a plan). A plan
        has no outcomes yet, so each predecessor's outcome is the context-free prediction and
        its residual zero (its expected value: a finger state the plan cannot know). The effect
        is the context model's prediction with this stroke's context minus its mean over
        reference contexts, the stroke's own controls held: the same model on both sides, so
        what the context model learned better from the stroke itself is not taken for context.

        The reference is the context in which the per-note model the plan starts from was
        learned: `reference`, strokes played in order (a play's warm-up; their contexts are
        built as a plan's are, from controls alone), or by default the training contexts
        (`REFERENCE_CONTEXTS`). Columns `TARGETS` (NaN where a target was not learned), one row
        per stroke; all zero for k = 0.
        """
        self._check()
        rows = self._controls_of(strokes.reset_index(drop=True))
        if self.k == 0 or rows.empty:
            return pd.DataFrame(0.0, index=range(len(rows)), columns=list(TARGETS))
        n_own = len(self.controls_) + 1
        with threadpool_limits(1):
            X = self._planned_features(rows)
            context = self.stage_.predict(X)
            contexts = getattr(self, "contexts_", None)
            if reference is not None and len(reference) >= 2:
                ref = self._planned_features(self._controls_of(reference.reset_index(drop=True)))[1:, n_own:]
                pick = np.unique(np.linspace(0, len(ref) - 1, min(REFERENCE_CONTEXTS, len(ref))).round().astype(int))
                contexts = ref[pick]
            if contexts is None:  # a model saved before the reference contexts: against k = 0
                typical = self.base_.predict(rows[list(self.controls_)].to_numpy(float))
            else:
                m = len(contexts)
                grid = np.column_stack([np.repeat(X[:, :n_own], m, axis=0), np.tile(contexts, (len(X), 1))])
                typical = self.stage_.predict(grid)[list(TARGETS)].groupby(np.repeat(np.arange(len(X)), m)).mean()
        return pd.DataFrame({name: context[name].to_numpy(float) - typical[name].to_numpy(float) for name in TARGETS})

    def _planned_features(self, rows: pd.DataFrame) -> FloatArray:
        """The context model's matrix of one planned sequence (controls only): each
        predecessor's outcome is its context-free prediction, its residual zero."""
        base = self.base_.predict(rows[list(self.controls_)].to_numpy(float))
        silent = base["p_silent"].to_numpy(float) >= 0.5
        base_on = base["on_velocity"].to_numpy(float)
        rows = rows.assign(sequence=0, silent=silent.astype(float), on_velocity=np.where(silent, np.nan, base_on),
                           midi_hold_s=np.where(silent, np.nan, base["midi_hold_s"].to_numpy(float)))
        return features(rows, self.controls_, self.k, base_on, np.where(silent, np.nan, 0.0))

    def _controls_of(self, frame: pd.DataFrame) -> pd.DataFrame:
        out = pd.DataFrame(index=range(len(frame)))
        for name in self.controls_:
            if name in frame:
                out[name] = frame[name].to_numpy(float)
            elif name in PARAMETERS and (followed := PARAMETERS[name].follows) is not None and followed in frame:
                out[name] = frame[followed].to_numpy(float)  # the up velocity follows the down velocity
            else:
                lo, hi = self.ranges_[name]
                out[name] = 0.5 * (lo + hi)
        if "note" not in out:
            out["note"] = frame["note"].to_numpy(float) if "note" in frame else np.nan
        return out
