"""`pianobot fit RUN… --model sequence`: grouped-CV of the sequence model by k, then save one.

The saved model uses the k the evaluation supports (`choose_k`): the lowest mean, over the
scored targets (on-velocity, inter-onset interval, lead — those measured), of the
cross-validated RMSE relative to k = 0; ties go to the smaller k. Loudness and timing count
alike: on the study's sequential log context halves the timing error and costs ~5 % in
loudness. The CV table travels with the file.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pianobot.analysis.learn.run import load_trials
from pianobot.analysis.sequence.evaluate import DEFAULT_KS, cross_validate_sequence
from pianobot.analysis.sequence.files import save_sequence_model
from pianobot.analysis.sequence.model import SequenceModel
from pianobot.analysis.sequence.strokes import stroke_sequences
from pianobot.errors import InputError
from pianobot.progress import NO_PROGRESS, Progress


@dataclass(frozen=True)
class SequenceFit:
    """The CV table (per-note baselines and the sequence model per k), the chosen k and the file."""

    cv: pd.DataFrame
    k: int
    saved: Path | None
    n_strokes: int
    n_sequences: int

    def context_gain(self) -> dict[str, float]:
        """Relative error change of the chosen k against k = 0 (negative: context helps)."""
        rows = {str(r["model"]): r for r in self.cv.to_dict(orient="records")}
        base, best = rows.get("sequence k=0"), rows[f"sequence k={self.k}"]
        if base is None:
            return {}
        out = {}
        for m in ("on_velocity_rmse", "ioi_rmse_s", "lead_rmse_s"):
            b, v = float(base[m]), float(best[m])
            if np.isfinite(b) and b > 0 and np.isfinite(v):
                out[m] = v / b - 1.0
        return out

    def to_dict(self) -> dict[str, Any]:
        return {"model": "sequence", "k": self.k, "n_strokes": self.n_strokes,
                "n_sequences": self.n_sequences, "saved": None if self.saved is None else str(self.saved),
                "context_gain": self.context_gain(), "cv": self.cv.to_dict(orient="records")}


SCORED: tuple[str, ...] = ("on_velocity_rmse", "ioi_rmse_s", "lead_rmse_s")


def choose_k(cv: pd.DataFrame) -> int:
    """The context length with the lowest mean relative RMSE against the smallest k."""
    seq = cv[cv["model"].str.startswith("sequence")].sort_values("k", kind="stable")
    ref = seq.iloc[0]
    metrics = [m for m in SCORED if np.isfinite(seq[m].to_numpy(float)).all() and float(ref[m]) > 0]
    if not metrics:
        return int(ref["k"])
    score = np.mean([seq[m].to_numpy(float) / float(ref[m]) for m in metrics], axis=0)
    return int(seq["k"].to_numpy()[int(np.argmin(np.round(score, 9)))])


def fit_sequence_runs(
    run_ids: Sequence[str], data_dir: Path, *, out_dir: Path | None, ks: Sequence[int] = DEFAULT_KS,
    per_note: Sequence[str] = ("gp",), folds: int = 5, seed: int = 0, workers: int | None = None,
    progress: Progress = NO_PROGRESS, rnn: bool = False,
) -> SequenceFit:
    """Cross-validate, choose k, fit on every stroke and save `sequence.json` under `out_dir`."""
    if not ks or min(ks) < 0:
        raise InputError(f"context lengths must be >= 0, got {list(ks)}", "--context")
    table = stroke_sequences(load_trials(run_ids, data_dir))
    cv = cross_validate_sequence(table, ks=ks, per_note=per_note, folds=folds, seed=seed,
                                 workers=workers, progress=progress, rnn=rnn)
    k = choose_k(cv)
    saved = None
    if out_dir is not None:
        with progress.task("fit on every stroke", total=1) as task:
            model = SequenceModel(k, seed).fit(table)
            task.advance()
        saved = save_sequence_model(model, Path(out_dir) / "sequence.json", cv=cv, runs=list(run_ids))
    return SequenceFit(cv, k, saved, table.n, table.n_sequences)
