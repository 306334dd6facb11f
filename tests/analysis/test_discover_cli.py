"""`pianobot discover` end to end: a stored scenario run in, JSON + HTML + model file out."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from pianobot.analysis import discover_scenarios as sc
from pianobot.cli import _register, app
from pianobot.physics.model import load_model


@pytest.fixture(scope="module")
def cli() -> CliRunner:
    _register()
    return CliRunner()


def test_discover_json_names_the_hidden_keybed(cli: CliRunner, tmp_path: Path) -> None:
    data = tmp_path / "data"
    scenario = sc.hidden_effect("keybed", "strong", seed=3)
    run_id = sc.write_run(sc.generate(scenario), data)
    start = tmp_path / "start.json"
    from pianobot.physics.model import save_model

    save_model(scenario.start, start)
    report = tmp_path / "discover.html"
    result = cli.invoke(
        app,
        [
            "discover",
            run_id,
            "--data",
            str(data),
            "--model",
            str(start),
            "--json",
            "--out",
            str(report),
        ],
    )
    assert result.exit_code == 0, result.output
    payload = json.loads(result.stdout)
    assert set(payload) >= {"iterations", "verdict"}
    first = payload["iterations"][0]
    assert first["accepted_effect"] == "keybed"
    assert {"candidates", "gap_before", "gap_after"} <= set(first)
    assert first["gap_after"]["primary"] < first["gap_before"]["primary"] / 5
    assert report.is_file() and "Missing effect: keybed" in report.read_text()
    assert "keybed" in load_model(payload["model_file"]).effects


def test_discover_bad_input_is_one_line_exit_2(cli: CliRunner, tmp_path: Path) -> None:
    data = tmp_path / "data"
    data.mkdir()
    result = cli.invoke(app, ["discover", "nope", "--data", str(data), "--json"])
    assert result.exit_code != 0
    assert result.exception is None or "Traceback" not in result.output
