"""`pianobot discover` end to end: a stored scenario run in, JSON + HTML + model file out."""

from __future__ import annotations

import json
import math
from pathlib import Path

import own_world as ow
import pytest
from cli_runner import invoke_cli

from pianobot.analysis.discover.candidates import family_of
from pianobot.physics.model import load_model

Run = tuple[pytest.CaptureFixture[str], pytest.MonkeyPatch]


@pytest.fixture
def cli(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> Run:
    return capsys, monkeypatch


def test_discover_names_two_effects_one_by_one(cli: Run, tmp_path: Path) -> None:
    """An end stop and friction hidden at once: each iteration names one more, the gap shrinks
    each time, and the report reads as evidence (mm, flagged bounds, named overlays)."""
    data = tmp_path / "data"
    run_id = ow.write_run(ow.reduced(ow.several(seed=61)), data)
    report = tmp_path / "discover.html"
    code, out, err = invoke_cli(["discover", run_id, "--data", str(data), "--json", "--out", str(report)], *cli)
    assert code == 0, err
    payload = json.loads(out)
    assert payload["mode"] == "trajectories"
    iterations = payload["iterations"]
    named = [it["accepted_effect"] for it in iterations if it["accepted_effect"]]
    assert {family_of(e) for e in named} == {"key_stop", "key_action"}
    assert iterations[-1]["accepted_effect"] is None  # the loop stops when nothing passes
    for it in iterations[:-1]:
        assert it["gap_after"]["position_m"] < it["gap_before"]["position_m"]
    # The criterion is on a readable scale, not 10¹⁰.
    assert all(abs(c["delta_ic"]) < 1e6 for it in iterations for c in it["candidates"])
    assert payload["measured_effects"] == ["arm_acceleration"]  # the arm log, not the key
    html = report.read_text()
    assert "Missing effect:" in html and " mm" in html and "dashed base model" in html
    model = load_model(payload["model_file"])
    assert set(named) <= set(model.effects.names) and "arm_acceleration" in model.effects


def test_discover_bad_input_is_one_line_exit_2(cli: Run, tmp_path: Path) -> None:
    data = tmp_path / "data"
    data.mkdir()
    code, out, err = invoke_cli(["discover", "nope", "--data", str(data), "--json"], *cli)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "Traceback" not in err


def test_gap_json_has_metres_and_millimetres(cli: Run, tmp_path: Path) -> None:
    data = tmp_path / "data"
    run_id = ow.write_run(ow.reduced(ow.control("clean", seed=33), n_speeds=3), data)
    code, out, err = invoke_cli(["discover", run_id, "--data", str(data), "--json"], *cli)
    assert code == 0, err
    gap = json.loads(out)["gap_before"]
    assert math.isclose(gap["position_mm"], 1e3 * gap["position_m"])
    assert json.loads(out)["accepted_effects"] == []
