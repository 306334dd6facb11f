"""A resume runs on the rig the run started with, unless --rig-override says otherwise (recorded)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pianobot.store import load_run
from robustness.harness import QUICKSTART, assert_cli_refused, cli, only_run

OTHER_RIG = "kind: sim\nsettle_s: {between_presses_s: 2.0}\n"


def test_resuming_on_another_rig_is_refused(killed_run: Path, tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str],
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    rig = tmp_path / "slow.yaml"
    rig.write_text(OTHER_RIG)
    run = only_run(killed_run).name
    assert_cli_refused(["sweep", QUICKSTART, "--resume", run, "--rig", rig, "--data", killed_run], killed_run,
            capsys, monkeypatch, "--rig", "differs", "settle_s.between_presses_s: 0.5 → 2.0",
            "--rig-override")


def test_a_rig_file_edited_since_the_run_started_is_another_rig(
    templates: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A run on a rig file; the file is edited; resume names no --rig: still refused.
    rig = tmp_path / "lab.yaml"
    rig.write_text("kind: sim\n")
    spec = tmp_path / "spec.yaml"
    spec.write_text(QUICKSTART.read_text().replace("rig: sim", "rig: lab.yaml"))
    data = tmp_path / "data"
    code, out, err = cli(["sweep", spec, "--data", data, "--json", "--no-progress"], capsys, monkeypatch)
    assert code == 0, err
    run = json.loads(out)["run_id"]
    rig.write_text("kind: sim\nsettle_s: {after_vacuum_change_s: 1.0}\n")
    assert_cli_refused(["sweep", spec, "--resume", run, "--data", data], data, capsys, monkeypatch,
            "settle_s.after_vacuum_change_s: 5.0 → 1.0")


def test_rig_override_is_recorded_per_session_and_shown(
    killed_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    rig = tmp_path / "slow.yaml"
    rig.write_text(OTHER_RIG)
    run = only_run(killed_run).name
    code, out, err = cli(["sweep", QUICKSTART, "--resume", run, "--rig", rig, "--rig-override",
                          "--data", killed_run, "--json", "--no-progress"], capsys, monkeypatch)
    assert code == 0, err
    meta = load_run(run, killed_run).meta
    assert meta["status"] == "completed" and meta["rig"]["mixed"] is True
    first, second = meta["rig_sessions"]
    assert first["sessions_from"] == 1 and first["file"] == "sim"
    assert second["sessions_from"] == 2 and second["file"] == str(rig)
    assert second["spec"]["settle_s"]["between_presses_s"] == 2.0
    code, out, _ = cli(["runs", "show", run, "--data", killed_run], capsys, monkeypatch)
    assert code == 0 and "MIXED: 2 rigs" in out
    report = tmp_path / "report.html"
    code, _, err = cli(["report", run, "--data", killed_run, "--out", report], capsys, monkeypatch)
    assert code == 0, err
    assert "MIXED: 2 rigs" in report.read_text()
