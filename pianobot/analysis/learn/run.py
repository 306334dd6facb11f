"""`pianobot fit`: trials of one or more runs → grouped-CV table and saved predictors."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from pianobot.analysis.learn.files import load_predictor, save_predictor
from pianobot.analysis.learn.models import MODEL_KINDS
from pianobot.analysis.learn.physical import PhysicsPredictor
from pianobot.analysis.learn.training import cross_validate_models, training_set
from pianobot.analysis.plausibility import Finding, as_dicts, fit_findings
from pianobot.errors import InputError
from pianobot.executor import ExecutorSettings, open_executor
from pianobot.progress import NO_PROGRESS, Progress
from pianobot.store import load_runs


def load_trials(run_ids: Sequence[str], data_dir: Path) -> pd.DataFrame:
    """The trials of every run, concatenated; a run named twice (or by two prefixes) counts once,
    as in identify and discover (`fit A A` learnt every keystroke twice)."""
    frames = []
    for run in load_runs(run_ids, data_dir):
        trials = run.trials
        if trials.empty:
            raise InputError("the run has no trials", run.run_id)
        frames.append(trials)
    return pd.concat(frames, ignore_index=True)


@dataclass(frozen=True)
class FitResult:
    """What `pianobot fit` produced: the CV table (with the `mean` baseline row), the saved
    predictor files by kind, and the plausibility findings (also stored in each file)."""

    cv: pd.DataFrame
    saved: dict[str, Path]
    findings: list[Finding] = field(default_factory=list)


def fit_runs(
    run_ids: Sequence[str], data_dir: Path, *, kinds: Sequence[str], out_dir: Path | None,
    folds: int = 5, seed: int = 0, physics_model: Path | None = None, progress: Progress = NO_PROGRESS,
    executor: ExecutorSettings | None = None,
) -> FitResult:
    """Cross-validate `kinds` and save one predictor per learned kind under `out_dir`.

    The CV folds run through the executor `executor` asks for (None: in this process) when
    their estimated time pays for it; the table does not depend on where they ran."""
    bad = [k for k in kinds if k not in MODEL_KINDS]
    if bad:
        raise InputError(f"unknown model {bad[0]!r}; valid: {', '.join(MODEL_KINDS)}, sequence, rnn", "--model")
    trials = load_trials(run_ids, data_dir)
    data = training_set(trials)
    physics = None
    if "physics" in kinds:
        physics = load_predictor(physics_model) if physics_model else PhysicsPredictor.published()
        if not isinstance(physics, PhysicsPredictor):
            # A learned predictor scored as "physics" on the keystrokes it was trained on read as
            # a perfect cross-validated model (RMSE 0.00, R² 1.000).
            raise InputError("is a learned predictor, not a keystroke model (identify or discover writes those); "
                             "the physics row scores a model fitted elsewhere", "--physics-model")
    settings = executor if executor is not None else ExecutorSettings(workers=1)
    table, fitted = cross_validate_models(data, kinds, folds=folds, seed=seed, physics=physics,
                                          progress=progress,
                                          executor=lambda work_s: open_executor(settings, work_s=work_s))
    findings = fit_findings(trials, table)
    saved: dict[str, Path] = {}
    if out_dir is not None:
        for kind in kinds:
            if kind in fitted:
                saved[kind] = save_predictor(fitted[kind], Path(out_dir) / f"predictor-{kind}.json",
                                             cv=table, runs=list(run_ids), warnings=as_dicts(findings))
    return FitResult(table, saved, findings)
