"""Sequence model files: `<name>.json` (schema `pianobot.sequence-model/1`) beside `<name>.joblib`.

The JSON sidecar is the file to load and to read: k, the controls, their training ranges, the
grouped-CV table, the training runs and the sha256 of the estimator file (a changed estimator
file is refused). Written and read by `learn.files`' model-file helpers, as the per-note
predictors are.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from pianobot.analysis.learn.files import read_estimator, read_sidecar, write_model_files
from pianobot.analysis.sequence.model import SequenceModel
from pianobot.errors import InputError

SEQUENCE_SCHEMA = "pianobot.sequence-model/1"


def save_sequence_model(model: SequenceModel, path: Path, *, cv: pd.DataFrame | None = None,
                        runs: Sequence[str] = ()) -> Path:
    """Write the sidecar and the estimator file (atomically, as every model file); returns the
    sidecar's path."""
    return write_model_files(path, model, {
        "schema": SEQUENCE_SCHEMA,
        "kind": "sequence",
        "k": model.k,
        "controls": list(model.controls_),
        "ranges": {c: list(v) for c, v in model.ranges_.items()},
        "n_strokes": model.n_strokes_,
        "n_sequences": model.n_sequences_,
        "estimator_file": None,
        "estimator_sha256": None,
        "runs": list(runs),
        "cv": [] if cv is None else json.loads(cv.to_json(orient="records")),
    })


def load_sequence_model(path: Path, sidecar: dict[str, Any] | None = None) -> SequenceModel:
    """Open a sequence model file (checking the estimator's name and hash).

    Raises:
        InputError: missing or changed files, or another schema.
    """
    path = Path(path)
    if sidecar is None:
        sidecar = read_sidecar(path, "sequence model")
    if not isinstance(sidecar, dict) or sidecar.get("schema") != SEQUENCE_SCHEMA:
        got = sidecar.get("schema") if isinstance(sidecar, dict) else None
        raise InputError(f"expected schema {SEQUENCE_SCHEMA!r}, got {got!r}", str(path))
    model = read_estimator(path, sidecar, "sequence model")
    if not isinstance(model, SequenceModel):
        raise InputError("the estimator file does not hold a pianobot sequence model", str(path))
    return model
