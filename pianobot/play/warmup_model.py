"""The model a warm-up fits: lead, loudness, hold and silence over the down velocity.

Fitted with `pianobot fit`'s learned predictors; which kind learns loudness and which the lead
is chosen by the error on keystrokes held out of the fit, as `pianobot fit` chooses.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pandas as pd
from sklearn.model_selection import GroupKFold

from pianobot.analysis.learn.predictors import OUTPUT_COLUMNS, FloatArray
from pianobot.analysis.learn.training import LearnedPredictor, training_set
from pianobot.errors import InputError

FIT_KINDS = ("gp", "poly", "spline")  # `pianobot fit`'s smooth kinds; the held-out error picks
CV_FOLDS = 6  # grouped folds of the held-out error (two strokes out of a dozen per fold)


class WarmUpPredictor:
    """A `StrokePredictor` fitted to warm-up keystrokes with the project's learned predictors.

    The note-on comes during the down move, before any hold: its delay and loudness (and
    whether the stroke sounds at all) do not depend on the hold. So they are learned from every
    keystroke over the down velocity (and vacuum) alone, and the MIDI hold over down velocity
    and arm hold. Every map sees the logarithm of the down velocity (loudness grows like a power
    of the speed, the lead like its inverse: both are smooth in log speed, where a dozen strokes
    pin them), and the lead is learned as the arm's travel to the note-on (speed × lead, nearly
    constant: the key sounds when the arm has pushed it far enough).

    Which of `pianobot fit`'s model kinds (`FIT_KINDS`) learns loudness and which the lead is
    decided as `pianobot fit` would: by the error on keystrokes held out of the fit (leave one
    speed out). `cv_` holds those errors per kind.
    """

    def __init__(self, loudness: LearnedPredictor, lead: LearnedPredictor, hold: LearnedPredictor,
                 speeds_mps: tuple[float, float], cv: pd.DataFrame, heard: tuple[float, float] = (1.0, 127.0)) -> None:
        self.loudness, self.lead, self.hold = loudness, lead, hold
        self.speeds_mps = speeds_mps  # the warm-up's slowest and fastest stroke
        self.cv_ = cv
        self.heard = heard  # the quietest and loudest on-velocity the warm-up heard

    @classmethod
    def fit(cls, trials: pd.DataFrame, seed: int = 0) -> WarmUpPredictor:
        """Fit the maps to executed warm-up trials (ok and silent rows), choosing kinds by CV."""
        speed = trials["down_velocity_mps"].to_numpy(float)
        onset = _logged(trials).assign(hold_s=0.0, t_on_s=trials["t_on_s"].to_numpy(float) * speed,
                                       midi_hold_s=np.nan)  # the hold map is learned apart
        fitted = {kind: _fit(kind, onset, seed) for kind in FIT_KINDS}
        cv = _held_out_errors(onset, fitted, seed)
        kind_v = str(cv.sort_values(["velocity_mae", "kind"]).iloc[0]["kind"])
        kind_l = str(cv.sort_values(["lead_rmse_s", "kind"]).iloc[0]["kind"])
        cv = cv.assign(loudness=cv["kind"] == kind_v, lead=cv["kind"] == kind_l)
        hold = _fit(kind_l, _logged(trials), seed, warm=fitted[kind_l])
        heard = trials.loc[trials["status"] == "ok", "on_velocity"].to_numpy(float)
        return cls(fitted[kind_v], fitted[kind_l], hold, (float(speed.min()), float(speed.max())), cv,
                   (float(np.nanmin(heard)), float(np.nanmax(heard))))

    def predict(self, frame: pd.DataFrame) -> pd.DataFrame:
        """Outcome per row (see `StrokePredictor.predict`)."""
        speed = frame["down_velocity_mps"].to_numpy(float)
        logged = frame.assign(down_velocity_mps=np.log(np.maximum(speed, 1e-6)))
        out = self.loudness.predict(logged)
        # No louder or quieter than anything heard: a fit between sparse strokes may overshoot.
        out["on_velocity"] = np.clip(out["on_velocity"].to_numpy(float), *self.heard)
        out["lead_s"] = self.lead.predict(logged)["lead_s"].to_numpy(float) / speed
        out["midi_hold_s"] = self.hold.predict(logged)["midi_hold_s"]
        return out[list(OUTPUT_COLUMNS)]


def _logged(trials: pd.DataFrame) -> pd.DataFrame:
    return trials.assign(down_velocity_mps=np.log(trials["down_velocity_mps"].to_numpy(float)))


def _fit(kind: str, frame: pd.DataFrame, seed: int, warm: LearnedPredictor | None = None) -> LearnedPredictor:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # GP kernel bounds on a dozen keystrokes: harmless
        return LearnedPredictor(kind, seed).fit(training_set(frame), warm=warm)


def _held_out_errors(onset: pd.DataFrame, fitted: dict[str, LearnedPredictor], seed: int) -> pd.DataFrame:
    """Per kind: loudness MAE and lead RMSE on sounded strokes held out (grouped by speed).

    As `pianobot fit` does: grouped folds (repeats of one speed never on both sides), each fold
    warm-started from the fit on all strokes.
    """
    sounded = np.isfinite(onset["on_velocity"].to_numpy(float)) & (onset["status"] == "ok").to_numpy()
    groups = np.unique(np.round(onset["down_velocity_mps"].to_numpy(float), 9), return_inverse=True)[1].ravel()
    folds = min(CV_FOLDS, int(np.unique(groups).size))
    splits = list(GroupKFold(n_splits=folds).split(onset, groups=groups)) if folds >= 2 else []
    speed = np.exp(onset["down_velocity_mps"].to_numpy(float))
    rows = []
    for kind, full in fitted.items():
        velocity, lead = np.full(len(onset), np.nan), np.full(len(onset), np.nan)
        for train, test in splits:
            try:
                model = _fit(kind, onset.iloc[train], seed, warm=full)
            except InputError:  # too few sounded strokes left to fit
                continue
            out = model.predict(onset.iloc[test])
            velocity[test], lead[test] = out["on_velocity"].to_numpy(float), out["lead_s"].to_numpy(float)
        dv = np.abs(velocity - onset["on_velocity"].to_numpy(float))[sounded]
        dl = ((lead - onset["t_on_s"].to_numpy(float)) / speed)[sounded]
        rows.append({"kind": kind, "velocity_mae": _mean_or_inf(dv), "lead_rmse_s": float(np.sqrt(_mean_or_inf(dl**2)))})
    return pd.DataFrame(rows)


def _mean_or_inf(values: FloatArray) -> float:
    values = values[np.isfinite(values)]
    return float(np.mean(values)) if values.size else math.inf
