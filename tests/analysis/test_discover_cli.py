"""`pianobot discover` end to end: a stored scenario run in, JSON + HTML + model file out."""

from __future__ import annotations

import json
from pathlib import Path

import own_world as sc
import pytest
from typer.testing import CliRunner

from pianobot.analysis.discover.decide import family_of
from pianobot.cli import _register, app
from pianobot.physics.model import load_model, save_model


@pytest.fixture(scope="module")
def cli() -> CliRunner:
    _register()
    return CliRunner()


def test_discover_names_several_effects_one_by_one(cli: CliRunner, tmp_path: Path) -> None:
    """Keybed + friction + mocap clock offset hidden at once: each iteration names one more."""
    data = tmp_path / "data"
    scenario = sc.reduced(sc.several(seed=61))
    run_id = sc.write_run(sc.generate(scenario), data)
    start = tmp_path / "start.json"
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
    iterations = payload["iterations"]
    assert all(
        {"accepted_effect", "candidates", "gap_before", "gap_after"} <= set(it) for it in iterations
    )
    named = [it["accepted_effect"] for it in iterations if it["accepted_effect"]]
    assert len(named) >= 2 and len(set(named)) == len(named)
    assert {family_of(e) for e in named} >= {family_of("keybed"), family_of("key_friction")}
    assert iterations[-1]["accepted_effect"] is None  # the loop stops when nothing passes
    for it in iterations[:-1]:
        assert it["gap_after"]["primary"] < it["gap_before"]["primary"]
    total = iterations[0]["gap_before"]["primary"] / iterations[-1]["gap_after"]["primary"]
    assert total > 5
    html = report.read_text()
    assert all(f"Missing effect: {e}" in html for e in named)
    model = load_model(payload["model_file"])
    assert set(named) <= set(model.effects.names)


def test_discover_bad_input_is_one_line_exit_2(cli: CliRunner, tmp_path: Path) -> None:
    data = tmp_path / "data"
    data.mkdir()
    result = cli.invoke(app, ["discover", "nope", "--data", str(data), "--json"])
    assert result.exit_code != 0
    assert result.exception is None or "Traceback" not in result.output
