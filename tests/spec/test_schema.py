"""The committed JSON schemas match the models (regenerate with `make schema`)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from pianobot.spec.schema import SCHEMA_FILES, schema_texts, write_schemas

REPO = Path(__file__).resolve().parents[2]
EXPERIMENTS = REPO / "experiments"


@pytest.mark.parametrize("name", sorted(SCHEMA_FILES))
def test_committed_schema_is_current(name: str) -> None:
    committed = (EXPERIMENTS / name).read_text(encoding="utf-8")
    assert committed == schema_texts()[name], (
        f"experiments/{name} is stale: run `make schema` "
        "(python -m pianobot.spec --write-schemas experiments) and commit it"
    )


def _objects(node: Any) -> list[dict[str, Any]]:
    """Every object schema (one with `properties`) inside a schema."""
    found: list[dict[str, Any]] = []
    if isinstance(node, dict):
        if "properties" in node:
            found.append(node)
        for value in node.values():
            found += _objects(value)
    elif isinstance(node, list):
        for value in node:
            found += _objects(value)
    return found


@pytest.mark.parametrize("name", sorted(SCHEMA_FILES))
def test_schema_is_strict_and_documented(name: str) -> None:
    schema = json.loads(schema_texts()[name])
    objects = _objects(schema)
    assert objects
    for obj in objects:
        assert obj.get("additionalProperties") is False, obj.get("title")
        for key, prop in obj["properties"].items():
            assert prop.get("description"), f"{obj.get('title')}.{key} has no description"


def test_spec_schema_knows_the_sweep_modes_and_parameters() -> None:
    schema = json.loads(schema_texts()["spec.schema.json"])
    defs = schema["$defs"]
    assert {"GridSweep", "RandomSweep", "LhsSweep", "Linspace", "Range"} <= set(defs)
    grid_params = defs["GridParams"]["properties"]
    assert set(grid_params) == {
        "note", "vacuum_kpa", "down_velocity_mps", "up_velocity_mps", "acceleration_mps2",
        "depth_m", "distance_m", "hold_s", "finger_angle_deg",
    }
    assert "m/s" in grid_params["down_velocity_mps"]["description"]


def test_write_schemas_command(tmp_path: Path) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "pianobot.spec", "--write-schemas", str(tmp_path)],
        capture_output=True, text=True, check=True, cwd=REPO,
    )
    assert "spec.schema.json" in result.stdout
    for name, text in schema_texts().items():
        assert (tmp_path / name).read_text(encoding="utf-8") == text
    assert sorted(p.name for p in write_schemas(tmp_path / "again")) == sorted(SCHEMA_FILES)
