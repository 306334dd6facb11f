"""`pianobot sweep` and `pianobot runs`: exit codes, one-line errors, JSON, no stray run folders."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from cli_runner import invoke_cli as cli

REPO = Path(__file__).resolve().parents[2]
QUICKSTART = REPO / "experiments" / "quickstart.yaml"

GOOD = """\
name: cli-test
finger: soft
note: 60
sweep:
  mode: grid
  params:
    vacuum_kpa: [0, -40]
    down_velocity_mps: [0.01, 0.04]
    depth_m: [0.025]
  fixed: {acceleration_mps2: 1.0, distance_m: 0.05}
record: [midi, arm]
"""




def _no_runs(data_dir: Path) -> bool:
    runs = data_dir / "runs"
    return not runs.exists() or not any(runs.iterdir())


BAD_SPECS = {
    "unknown key": (GOOD + "colour: red\n", "colour"),
    "wrong unit type": (GOOD.replace("depth_m: [0.025]", "depth_m: ['25 mm']"), "depth_m"),
    "empty grid": (GOOD.replace("depth_m: [0.025]", "depth_m: []"), "depth_m"),
    "out of envelope": (GOOD.replace("[0.01, 0.04]", "[0.01, 0.4]"), "down_velocity_mps"),
    "yaml syntax": (GOOD.replace("finger: soft", "finger: [soft"), "bad.yaml"),
}


@pytest.mark.parametrize("case", sorted(BAD_SPECS))
def test_bad_specs_exit_2_with_one_line_and_leave_no_run_folder(
    case: str, tmp_path: Path, data_dir: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    text, named = BAD_SPECS[case]
    spec = tmp_path / "bad.yaml"
    spec.write_text(text)
    for extra in ([], ["--dry-run"], ["--json"]):
        code, out, err = cli(["sweep", str(spec), "--data", str(data_dir), *extra], capsys, monkeypatch)
        assert code == 2, (case, extra, out, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: ") and named in lines[0], (case, err)
        assert "Traceback" not in err and out == ""
    assert _no_runs(data_dir)


def test_unreadable_spec_exits_2(tmp_path: Path, data_dir: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    code, _, err = cli(["sweep", str(tmp_path / "missing.yaml"), "--data", str(data_dir)], capsys, monkeypatch)
    assert code == 2 and "missing.yaml" in err and len(err.strip().splitlines()) == 1
    assert _no_runs(data_dir)


def test_dry_run_prints_the_plan_and_moves_nothing(
    data_dir: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    code, out, _ = cli(["sweep", str(QUICKSTART), "--dry-run", "--data", str(data_dir)], capsys, monkeypatch)
    assert code == 0 and "16 trials" in out and "lab time" in out
    code, out, _ = cli(["sweep", str(QUICKSTART), "--dry-run", "--json", "--data", str(data_dir)], capsys, monkeypatch)
    payload = json.loads(out)
    assert code == 0 and payload["trials"] == 16 and payload["errors"] == 0
    assert payload["lab_time"]["total_s"] > 0
    assert _no_runs(data_dir)
    # The rig in use is named (it named the spec's even with --rig: misleading before a lab run).
    lab = REPO / "experiments" / "rigs" / "ur5-lab.yaml"
    code, out, _ = cli(["sweep", str(QUICKSTART), "--dry-run", "--rig", str(lab), "--data", str(data_dir)],
                       capsys, monkeypatch)
    said = " ".join(out.split())  # a narrow terminal wraps the line
    assert code == 0 and f"rig {lab}," in said and "(2 changes)" in said
    # What the run would refuse, the dry run refuses too; a dry run of a resume is no such thing.
    for extra, where in ((["--seed", "-1"], "--seed"), (["--resume", "nope"], "--resume")):
        code, out, err = cli(["sweep", str(QUICKSTART), "--dry-run", *extra, "--data", str(data_dir)],
                             capsys, monkeypatch)
        assert code == 2 and where in err and len(err.strip().splitlines()) == 1


def test_sweep_json_then_runs_and_runs_show(
    tmp_path: Path, data_dir: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    spec = tmp_path / "good.yaml"
    spec.write_text(GOOD)
    code, out, err = cli(["sweep", str(spec), "--data", str(data_dir), "--json", "--seed", "4"], capsys, monkeypatch)
    assert code == 0, err
    result = json.loads(out)
    assert result["status"] == "completed" and result["trials"] == 4
    assert 0 <= result["silent"] <= 4 and result["run_id"].split("-")[2] == "cli"
    run_id = result["run_id"]

    code, out, _ = cli(["runs", "--data", str(data_dir), "--json"], capsys, monkeypatch)
    (listed,) = json.loads(out)
    assert code == 0 and listed["run_id"] == run_id and listed["trials_done"] == 4
    assert listed["trials_planned"] == 4 and listed["status"] == "completed"

    code, out, _ = cli(["runs", "show", run_id[:22], "--data", str(data_dir), "--json"], capsys, monkeypatch)
    shown = json.loads(out)
    assert code == 0 and shown["run_id"] == run_id and shown["seed"] == 4
    assert shown["counts"]["ok"] + shown["counts"]["silent"] == 4

    code, out, _ = cli(["runs", "--data", str(data_dir)], capsys, monkeypatch)
    assert code == 0 and run_id[:15] in out
    code, out, _ = cli(["runs", "show", run_id, "--data", str(data_dir)], capsys, monkeypatch)
    assert code == 0 and "completed" in out

    code, out, _ = cli(["sweep", str(spec), "--data", str(data_dir)], capsys, monkeypatch)
    assert code == 0 and "pianobot runs show" in out and "load_run" in out


def test_runs_with_no_data_and_unknown_run(
    data_dir: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    code, out, _ = cli(["runs", "--data", str(data_dir), "--json"], capsys, monkeypatch)
    assert code == 0 and json.loads(out) == []
    code, out, _ = cli(["runs", "--data", str(data_dir)], capsys, monkeypatch)
    assert code == 0 and "no runs" in out
    code, _, err = cli(["runs", "show", "nope", "--data", str(data_dir)], capsys, monkeypatch)
    assert code == 2 and "pianobot runs" in err and len(err.strip().splitlines()) == 1
    code, _, err = cli(["sweep", "--resume", "nope", "--data", str(data_dir)], capsys, monkeypatch)
    assert code == 2 and "pianobot runs" in err
