"""Predictor files: `load_predictor` opens a physics model or a learned predictor; `save_predictor`
writes a learned one.

This module sits above both kinds of predictor (`learn.physical`, `learn.training`), which know
nothing of files of the other kind: no import cycle. Files of a learned predictor: `<name>.json`
(schema `pianobot.predictor/1`: kind, inputs, ranges, CV table, training runs, hash of the
estimator file) beside `<name>.joblib`; the JSON is written last, atomically, so a reader never
sees a sidecar whose estimator is not complete.
"""

from __future__ import annotations

import hashlib
import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import joblib
import pandas as pd

from pianobot.analysis.learn.physical import PhysicsPredictor
from pianobot.analysis.learn.predictors import StrokePredictor
from pianobot.analysis.learn.training import LearnedPredictor
from pianobot.atomic_files import write_bytes_atomic, write_text_atomic
from pianobot.errors import InputError
from pianobot.physics.model import MODEL_SCHEMA, load_model

PREDICTOR_SCHEMA = "pianobot.predictor/1"


def load_predictor(path: str | Path) -> StrokePredictor:
    """Open a predictor file: a physics model (`pianobot.model/1`) or a learned one
    (`pianobot.predictor/1`, written by `pianobot fit`).

    Raises:
        InputError: missing file, not JSON, or another schema.
    """
    source = Path(path)
    try:
        payload = json.loads(source.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError("predictor file not found", str(source)) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"not a JSON predictor or model file ({exc})", str(source)) from None
    schema = payload.get("schema") if isinstance(payload, dict) else None
    if schema == MODEL_SCHEMA:
        return PhysicsPredictor(load_model(source))
    if schema == PREDICTOR_SCHEMA:
        return load_learned(source, payload)
    raise InputError(
        f"expected schema {MODEL_SCHEMA!r} or {PREDICTOR_SCHEMA!r}, got {schema!r}", str(source)
    )


def save_predictor(model: LearnedPredictor, path: Path, *, cv: pd.DataFrame | None = None,
                   runs: Sequence[str] = (), warnings: Sequence[dict[str, str]] = ()) -> Path:
    """Write `<path>.json` (sidecar, the file to load) and `<path stem>.joblib`; returns the JSON path."""
    path = Path(path)
    json_path = path if path.suffix == ".json" else path.with_suffix(".json")
    blob = json_path.with_suffix(".joblib")
    json_path.parent.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    joblib.dump(model, buffer)
    estimator = buffer.getvalue()
    write_bytes_atomic(blob, estimator)
    import pianobot

    sidecar = {
        "schema": PREDICTOR_SCHEMA,
        "kind": model.kind,
        "inputs": list(model.inputs_),
        "ranges": {k: list(v) for k, v in model.ranges_.items()},
        "defaults": model.defaults_,
        "estimator_file": blob.name,
        "estimator_sha256": hashlib.sha256(estimator).hexdigest(),
        "runs": list(runs),
        "cv": [] if cv is None else json.loads(cv.to_json(orient="records")),
        "warnings": list(warnings),  # plausibility findings of the fit (pianobot.analysis.plausibility)
        "pianobot_version": getattr(pianobot, "__version__", "unknown"),
    }
    write_text_atomic(json_path, json.dumps(sidecar, indent=2))
    return json_path


def load_learned(path: Path, sidecar: dict[str, Any]) -> LearnedPredictor:
    """Load the estimator a sidecar names, after checking its hash (a changed file is refused)."""
    name = sidecar.get("estimator_file")
    # A plain file name beside the sidecar: never a path elsewhere, nothing the OS chokes on.
    if (not isinstance(name, str) or not name or len(name) > 255 or "\x00" in name
            or Path(name).name != name or name in (".", "..")):
        raise InputError(f"estimator_file should be a file name beside the predictor, got {str(name)[:40]!r}",
                         str(path))
    blob = Path(path).parent / name
    if not blob.is_file():
        raise InputError(f"estimator file {blob.name!r} named by the predictor is missing", str(path))
    estimator = blob.read_bytes()  # hashed and loaded from the same bytes
    digest = hashlib.sha256(estimator).hexdigest()
    if digest != sidecar.get("estimator_sha256"):
        raise InputError(f"estimator file {blob.name!r} does not match its recorded sha256", str(path))
    model = joblib.load(io.BytesIO(estimator))
    if not isinstance(model, LearnedPredictor):
        raise InputError("the estimator file does not hold a pianobot predictor", str(blob))
    return model
