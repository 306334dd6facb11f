"""`pianobot import ...`: JSON keys, exit code 2 and nothing stored for a bad file."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from pianobot.cli import _register, app, main

runner = CliRunner()
_register()


def invoke(*args: str) -> tuple[int, str]:
    result = runner.invoke(app, list(args))
    return result.exit_code, result.stdout


def run_main(
    args: list[str], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> tuple[int, str, str]:
    """The real entry point in-process: exit code, stdout, stderr."""
    monkeypatch.setattr(sys, "argv", ["pianobot", *args])
    with pytest.raises(SystemExit) as stop:
        main()
    captured = capsys.readouterr()
    return int(stop.value.code or 0), captured.out, captured.err


def soft_log(tmp_path: Path) -> Path:
    lines = [
        repr(
            {
                "control": [60, 45, 0.5, 0.03, 0.04, 0.05, 0],
                "midi": [[[144, 57, 4, 0], 1000], [[128, 57, 9, 0], 2200]],
            }
        ),
        repr({"control": [60, 45, 0.5, 0.04, 0.04, 0.05, 0], "midi": []}),
        "{'control': [60, 45,",
    ]
    path = tmp_path / "soft_60_angle_45.txt"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_keystroke_log_json(tmp_path: Path, data_dir: Path) -> None:
    code, out = invoke(
        "import", "keystroke-log", str(soft_log(tmp_path)), "--data", str(data_dir), "--json"
    )
    assert code == 0
    payload = json.loads(out)
    assert {"run_id", "trials", "silent", "skipped_lines"} <= set(payload)
    assert (payload["trials"], payload["silent"]) == (2, 1)
    assert payload["skipped_lines"][0]["line"] == 3 and payload["skipped_lines"][0]["reason"]
    assert (data_dir / "runs" / payload["run_id"] / "run.json").is_file()


def test_keystroke_log_table_output(tmp_path: Path, data_dir: Path) -> None:
    code, out = invoke("import", "keystroke-log", str(soft_log(tmp_path)), "--layout", "soft-2022",
                       "--data", str(data_dir))  # fmt: skip
    assert code == 0 and "soft-2022" in out and "line 3" in out


def test_force_log_json(tmp_path: Path, data_dir: Path) -> None:
    path = tmp_path / "force.txt"
    path.write_text("\n".join(f"Analog reading = {r}" for r in [0] * 30 + [20] * 20 + [0] * 30))
    code, out = invoke(
        "import", "force-log", str(path), "--rate-hz", "50", "--data", str(data_dir), "--json"
    )
    assert code == 0
    payload = json.loads(out)
    assert payload["bursts"] == 1 and payload["trials"] == 1 and payload["rate_hz"] == 50


def test_mocap_json(tmp_path: Path, data_dir: Path) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "io"))
    from motive_synth import motive_csv

    take = motive_csv(
        tmp_path / "take.csv", duration_s=8.0, starts_s=[1.0, 4.0], speeds_mps=[0.02, 0.04]
    )
    code, out = invoke("import", "mocap", str(take), "--marker", "arm=Unlabeled:100",
                       "--data", str(data_dir), "--json")  # fmt: skip
    assert code == 0
    payload = json.loads(out)
    assert payload["keystrokes"] == 2 and payload["roles"]["arm"] == "Unlabeled:100"
    assert "clock_offset_s" not in payload


def test_mocap_vacuum_is_stored_on_every_trial(
    tmp_path: Path,
    data_dir: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "io"))
    from motive_synth import motive_csv

    from pianobot.store import load_run

    take = motive_csv(tmp_path / "take.csv", duration_s=8.0, starts_s=[1.0, 4.0], speeds_mps=[0.02, 0.04])
    code, out = invoke("import", "mocap", str(take), "--marker", "arm=Unlabeled:100",
                       "--vacuum-kpa", "-40", "--data", str(data_dir), "--json")  # fmt: skip
    assert code == 0
    run = load_run(json.loads(out)["run_id"], data_dir)
    assert run.trials["vacuum_kpa"].tolist() == [-40.0, -40.0]
    assert run.meta["vacuum_kpa"] == -40.0
    # A magnitude reads as the gauge pressure, as in identify and discover; beyond 100 kPa, refused.
    code, _, err = run_main(["import", "mocap", str(take), "--vacuum-kpa", "150", "--data", str(data_dir)],
                            monkeypatch, capsys)  # fmt: skip
    assert code == 2 and "--vacuum-kpa" in err and err.count("\n") == 1


@pytest.mark.parametrize("command", ["keystroke-log", "force-log", "mocap"])
def test_bad_file_exit_2_and_no_run(
    tmp_path: Path,
    data_dir: Path,
    command: str,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    bad = tmp_path / "bad.bin"
    bad.write_bytes(b"\x00\xff\x00 not data")
    code, out, err = run_main(
        ["import", command, str(bad), "--data", str(data_dir), "--json"], monkeypatch, capsys
    )
    assert code == 2
    assert err.startswith("error: ") and err.count("\n") == 1 and str(bad) in err
    assert "Traceback" not in err and out == ""
    runs = data_dir / "runs"
    assert not runs.exists() or not any(runs.iterdir())


def test_bad_marker_option_exit_2(
    tmp_path: Path,
    data_dir: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    args = [
        "import",
        "mocap",
        str(tmp_path / "missing.csv"),
        "--marker",
        "arm",
        "--data",
        str(data_dir),
    ]
    code, _, err = run_main(args, monkeypatch, capsys)
    assert code == 2 and "--marker" in err


def test_fixture_soft_60_cli(zhang2022: Path, data_dir: Path) -> None:
    path = zhang2022 / "data/soft/ctrl_midi/soft_60_angle_45.txt"
    code, out = invoke("import", "keystroke-log", str(path), "--data", str(data_dir), "--json")
    payload = json.loads(out)
    assert code == 0 and (payload["trials"], payload["silent"]) == (135, 32)


def test_keystroke_log_says_where_the_run_was_written(tmp_path: Path, data_dir: Path) -> None:
    code, out = invoke("import", "keystroke-log", str(soft_log(tmp_path)), "--data", str(data_dir))
    assert code == 0
    run_dir = out.split("written to", 1)[1].split()[0]
    assert (Path(run_dir) / "run.json").is_file() and str(data_dir) in run_dir
    code, out = invoke("import", "keystroke-log", str(soft_log(tmp_path)), "--data", str(data_dir), "--json")
    assert Path(json.loads(out)["run_dir"]).is_dir()


def test_keystroke_log_declared_columns(
    tmp_path: Path, data_dir: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "eight.txt"
    path.write_text(repr({"control": [0, 1.0, 0.8, 0.2, 0.3, 0.03, 0.5, 0.01],
                          "midi": [[[144, 60, 50, 0], 900], [[128, 60, 70, 0], 1900]]}) + "\n")  # fmt: skip
    code, _, err = run_main(["import", "keystroke-log", str(path), "--data", str(data_dir)], monkeypatch, capsys)
    assert code == 2 and err.count("\n") == 1 and "line 1: 8 control values" in err and "--columns" in err
    columns = "finger_angle_deg,acceleration_mps2,up_acceleration_mps2,down_velocity_mps,up_velocity_mps,distance_m,hold_s,depth_m"
    code, out = invoke("import", "keystroke-log", str(path), "--columns", columns, "--finger", "rigid",
                       "--data", str(data_dir), "--json")  # fmt: skip
    assert code == 0 and json.loads(out)["layout"] == "declared" and json.loads(out)["sounded"] == 1
    code, _, err = run_main(["import", "keystroke-log", str(path), "--columns", "dwell_s", "--data", str(data_dir)],
                            monkeypatch, capsys)  # fmt: skip
    assert code == 2 and err.startswith("error: --columns:") and "dwell_s" in err and err.count("\n") == 1
