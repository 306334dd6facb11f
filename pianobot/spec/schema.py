"""JSON schemas of the spec and rig files, generated from the models (for editors and CI)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from pianobot.spec.experiment import ExperimentSpec
from pianobot.spec.rig import RigSpec

SCHEMA_FILES: dict[str, type[ExperimentSpec] | type[RigSpec]] = {
    "spec.schema.json": ExperimentSpec,
    "rig.schema.json": RigSpec,
}


def schema_of(model: type[ExperimentSpec] | type[RigSpec]) -> dict[str, Any]:
    """The JSON schema (draft 2020-12) that validates one kind of file."""
    schema = model.model_json_schema()
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **schema}


def schema_texts() -> dict[str, str]:
    """File name → the schema as committed (sorted keys, 2-space indent, trailing newline)."""
    return {
        name: json.dumps(schema_of(model), indent=2, sort_keys=True, ensure_ascii=False) + "\n"
        for name, model in SCHEMA_FILES.items()
    }


def write_schemas(folder: str | Path) -> list[Path]:
    """Write spec.schema.json and rig.schema.json into `folder`; return the paths written."""
    target = Path(folder)
    target.mkdir(parents=True, exist_ok=True)
    written = []
    for name, text in schema_texts().items():
        path = target / name
        path.write_text(text, encoding="utf-8")
        written.append(path)
    return written
