"""Sequence model files: `<name>.json` (schema `pianobot.sequence-model/1`) beside `<name>.joblib`.

The JSON sidecar is the file to load and to read: k, the controls, their training ranges, the
grouped-CV table, the training runs and the sha256 of the estimator file (a changed estimator
file is refused, as for the per-note predictors).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import joblib
import pandas as pd

from pianobot.analysis.sequence.model import SequenceModel
from pianobot.errors import InputError

SEQUENCE_SCHEMA = "pianobot.sequence-model/1"


def save_sequence_model(model: SequenceModel, path: Path, *, cv: pd.DataFrame | None = None,
                        runs: Sequence[str] = ()) -> Path:
    """Write the sidecar and the estimator file; returns the sidecar's path."""
    import pianobot

    path = Path(path)
    json_path = path if path.suffix == ".json" else path.with_suffix(".json")
    blob = json_path.with_suffix(".joblib")
    json_path.parent.mkdir(parents=True, exist_ok=True)
    joblib.dump(model, blob)
    sidecar: dict[str, Any] = {
        "schema": SEQUENCE_SCHEMA,
        "kind": "sequence",
        "k": model.k,
        "controls": list(model.controls_),
        "ranges": {c: list(v) for c, v in model.ranges_.items()},
        "n_strokes": model.n_strokes_,
        "n_sequences": model.n_sequences_,
        "estimator_file": blob.name,
        "estimator_sha256": hashlib.sha256(blob.read_bytes()).hexdigest(),
        "runs": list(runs),
        "cv": [] if cv is None else json.loads(cv.to_json(orient="records")),
        "pianobot_version": getattr(pianobot, "__version__", "unknown"),
    }
    json_path.write_text(json.dumps(sidecar, indent=2), encoding="utf-8")
    return json_path


def load_sequence_model(path: Path, sidecar: dict[str, Any] | None = None) -> SequenceModel:
    """Open a sequence model file (checking the estimator's hash).

    Raises:
        InputError: missing or changed files, or another schema.
    """
    path = Path(path)
    if sidecar is None:
        try:
            sidecar = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise InputError("sequence model file not found", str(path)) from None
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise InputError(f"not a JSON sequence model file ({exc})", str(path)) from None
    if not isinstance(sidecar, dict) or sidecar.get("schema") != SEQUENCE_SCHEMA:
        got = sidecar.get("schema") if isinstance(sidecar, dict) else None
        raise InputError(f"expected schema {SEQUENCE_SCHEMA!r}, got {got!r}", str(path))
    blob = path.parent / str(sidecar.get("estimator_file", ""))
    if not blob.is_file():
        raise InputError(f"estimator file {blob.name} named by the sequence model is missing", str(path))
    if hashlib.sha256(blob.read_bytes()).hexdigest() != sidecar.get("estimator_sha256"):
        raise InputError(f"estimator file {blob.name} does not match its recorded sha256", str(path))
    model = joblib.load(blob)
    if not isinstance(model, SequenceModel):
        raise InputError("the estimator file does not hold a pianobot sequence model", str(blob))
    return model
