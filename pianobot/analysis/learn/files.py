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
    payload = read_sidecar(source, "predictor or model")
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
    return write_model_files(path, model, {
        "schema": PREDICTOR_SCHEMA,
        "kind": model.kind,
        "inputs": list(model.inputs_),
        "ranges": {k: list(v) for k, v in model.ranges_.items()},
        "defaults": model.defaults_,
        "estimator_file": None,
        "estimator_sha256": None,
        "runs": list(runs),
        "cv": [] if cv is None else json.loads(cv.to_json(orient="records")),
        "warnings": list(warnings),  # plausibility findings of the fit (pianobot.analysis.plausibility)
    })


def load_learned(path: Path, sidecar: dict[str, Any]) -> LearnedPredictor:
    """Load the estimator a sidecar names, after checking its hash (a changed file is refused)."""
    model = read_estimator(path, sidecar, "predictor")
    if not isinstance(model, LearnedPredictor):
        raise InputError("the estimator file does not hold a pianobot predictor", str(path))
    return model


def write_model_files(path: Path, estimator: object, sidecar: dict[str, Any]) -> Path:
    """Write a fitted estimator as `<name>.joblib` beside its JSON sidecar `<name>.json`, both
    atomically, the sidecar last; returns the sidecar's path.

    `sidecar`'s `estimator_file` and `estimator_sha256` are filled in (where the caller placed
    them, so the file reads in the caller's order) and `pianobot_version` is added.
    """
    import pianobot

    path = Path(path)
    json_path = path if path.suffix == ".json" else path.with_suffix(".json")
    blob = json_path.with_suffix(".joblib")
    json_path.parent.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    joblib.dump(estimator, buffer)
    data = buffer.getvalue()
    write_bytes_atomic(blob, data)
    filled = {**sidecar, "estimator_file": blob.name, "estimator_sha256": hashlib.sha256(data).hexdigest(),
              "pianobot_version": getattr(pianobot, "__version__", "unknown")}
    write_text_atomic(json_path, json.dumps(filled, indent=2))
    return json_path


def read_sidecar(path: Path, what: str) -> Any:
    """The parsed JSON of a model file (`what` names it in errors: "predictor", ...).

    Raises:
        InputError: missing, unreadable or not JSON.
    """
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{what} file not found", str(path)) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"not a JSON {what} file ({exc})", str(path)) from None


def read_estimator(path: Path, sidecar: dict[str, Any], what: str) -> object:
    """The estimator a sidecar names, loaded after checking its sha256 (a changed file is refused).

    Raises:
        InputError: the name is not a plain file name beside the sidecar, the file is missing,
            or its bytes do not match the recorded sha256.
    """
    name = sidecar.get("estimator_file")
    # A plain file name beside the sidecar: never a path elsewhere, nothing the OS chokes on.
    if (not isinstance(name, str) or not name or len(name) > 255 or "\x00" in name
            or Path(name).name != name or name in (".", "..")):
        raise InputError(f"estimator_file should be a file name beside the {what}, got {str(name)[:40]!r}",
                         str(path))
    blob = Path(path).parent / name
    if not blob.is_file():
        raise InputError(f"estimator file {blob.name!r} named by the {what} is missing", str(path))
    estimator = blob.read_bytes()  # hashed and loaded from the same bytes
    if hashlib.sha256(estimator).hexdigest() != sidecar.get("estimator_sha256"):
        raise InputError(f"estimator file {blob.name!r} does not match its recorded sha256", str(path))
    loaded: object = joblib.load(io.BytesIO(estimator))
    return loaded
