"""The UR arm log (ur_rtde's file recording) as a lab records it beside a Motive take: read on
its own, imported with the take, and what it lets discovery measure (the mocap clock)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from cli_runner import invoke_cli
from hypothesis import given, settings
from hypothesis import strategies as st

from pianobot.analysis.discover.measured import arm_checks, clock_check
from pianobot.analysis.greybox.load import load_keystrokes, read_schedule
from pianobot.errors import InputError
from pianobot.io.arm_log import read_arm_log
from pianobot.io.importers import import_mocap
from pianobot.store import list_runs, load_run
from tests.truth import materialise, scenario

POSE = [f"{name}_{i}" for name in ("actual_TCP_pose", "target_TCP_pose") for i in range(6)]


def _log(path: Path, stamps: list[float], z: list[float], sep: str = ",", extra: str = "") -> Path:
    """A recording in ur_rtde's layout: timestamp, actual and target TCP pose, one row a cycle."""
    header = sep.join(["timestamp", *POSE]) + (sep + extra if extra else "")
    rows = [sep.join(f"{v:.6f}" for v in [s, 0.41, -0.18, h, 2.2, -2.2, 0.0, 0.41, -0.18, h + 1e-4, 2.2, -2.2, 0.0]
                     + ([1.0] if extra else [])) for s, h in zip(stamps, z, strict=True)]
    path.write_text("\n".join([header, *rows]) + "\n", encoding="utf-8")
    return path


def test_a_recording_reads_as_downward_travel_from_its_first_row(tmp_path: Path) -> None:
    stamps = [1000.0 + 0.008 * k for k in range(20)]
    z = [0.25 - 0.001 * k for k in range(20)]
    log = read_arm_log(_log(tmp_path / "arm.csv", stamps, z, extra="actual_q_0"))
    assert log.first_timestamp_s == pytest.approx(1000.0)
    assert log.rate_hz == pytest.approx(125.0)
    assert log.t_s[0] == 0.0 and log.t_s[-1] == pytest.approx(0.152)
    # z up in the base frame, x0 down in pianobot's: the arm going down 1 mm a cycle.
    assert np.diff(log.down_m) == pytest.approx(np.full(19, 0.001))
    assert log.target_down_m is not None
    assert log.target_down_m - log.down_m == pytest.approx(np.full(20, -1e-4))
    assert not log.dropped_last_row


def test_urs_own_recorder_writes_spaces_and_is_read_too(tmp_path: Path) -> None:
    stamps = [5.0 + 0.002 * k for k in range(12)]
    log = read_arm_log(_log(tmp_path / "arm.txt", stamps, [0.3] * 12, sep=" "))
    assert log.rate_hz == pytest.approx(500.0) and np.all(log.down_m == log.down_m[0])


def test_a_last_row_cut_short_by_the_recording_stopping_is_dropped(tmp_path: Path) -> None:
    path = _log(tmp_path / "arm.csv", [0.008 * k for k in range(15)], [0.2] * 15)
    path.write_text(path.read_text() + "0.120000,0.41,-0.1", encoding="utf-8")
    log = read_arm_log(path)
    assert log.t_s.size == 15 and log.dropped_last_row


def test_what_recorders_and_spreadsheets_write_reads_as_the_recording(tmp_path: Path) -> None:
    stamps = [2000.0 + 0.008 * k for k in range(30)]
    z = [0.25 - 0.0003 * k for k in range(30)]
    plain = read_arm_log(_log(tmp_path / "arm.csv", stamps, z))
    lines = (tmp_path / "arm.csv").read_text().splitlines()
    variants = {
        # A recorder that wrote one controller state twice.
        "repeated": [*lines[:8], lines[7], lines[7], *lines[8:]],
        # A European spreadsheet's re-save: semicolons and decimal commas.
        "semicolons": [line.replace(",", ";").replace(".", ",") for line in lines],
        "quoted": [",".join(f'"{f}"' for f in lines[0].split(",")), *lines[1:]],
        "trailing separator": [lines[0], *(line + "," for line in lines[1:])],
        # Capitalised names (a spreadsheet's re-save) and a person's notes above and between rows.
        "capitalised": [lines[0].replace("timestamp", "Timestamp").replace("actual_TCP", "Actual_TCP"), *lines[1:]],
        "notes": ["# robot 2, tool v3", lines[0], *lines[1:5], "# operator paused here", *lines[5:]],
    }
    for name, text in variants.items():
        path = tmp_path / f"{name}.csv"
        path.write_text("\n".join(text) + "\n", encoding="utf-8")
        log = read_arm_log(path)
        assert log.t_s == pytest.approx(plain.t_s, abs=1e-9), name
        assert log.down_m == pytest.approx(plain.down_m, abs=1e-9), name
        assert log.first_timestamp_s == pytest.approx(plain.first_timestamp_s), name
    assert read_arm_log(tmp_path / "repeated.csv").repeated_rows == 2 and plain.repeated_rows == 0


@pytest.mark.parametrize(("edit", "where", "what"), [
    (lambda lines: ["time,x,y,z", *lines[1:]], ":1", "no column timestamp"),
    (lambda lines: [*lines[:5], lines[5].replace(",0.200000,", ",n/a,"), *lines[6:]], ":6", "expected 13 numbers"),
    (lambda lines: [*lines[:5], lines[7], lines[6], *lines[8:]], ":7", "goes back"),
    (lambda lines: lines[:4], "arm.csv", "only 3 rows"),
    (lambda lines: [], "arm.csv", "empty"),
])
def test_a_bad_log_is_one_error_naming_the_file_and_line(tmp_path: Path, edit, where: str, what: str) -> None:  # type: ignore[no-untyped-def]
    path = _log(tmp_path / "arm.csv", [0.008 * k for k in range(15)], [0.2] * 15)
    path.write_text("\n".join(edit(path.read_text().splitlines())) + "\n", encoding="utf-8")
    with pytest.raises(InputError, match=what) as caught:
        read_arm_log(path)
    assert caught.value.where.endswith(where)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-0.5, 0.5, allow_nan=False), min_size=10, max_size=60),
       st.floats(0.0, 1e6, allow_nan=False), st.sampled_from([",", " "]))
def test_any_recording_reads_back_to_the_micrometre(heights: list[float], boot_s: float, sep: str) -> None:
    import tempfile

    with tempfile.TemporaryDirectory() as scratch:
        stamps = [boot_s + 0.008 * k for k in range(len(heights))]
        log = read_arm_log(_log(Path(scratch) / "arm.csv", stamps, heights, sep=sep))
    assert log.t_s.size == len(heights) and np.all(np.diff(log.t_s) > 0)
    assert np.abs(log.down_m + np.round(heights, 6)).max() < 1e-9
    assert math.isclose(log.rate_hz, 125.0, rel_tol=1e-3)


# The truth lab (tests/truth) writes each take's arm log as a UR lab records it: 125 Hz, on the
# arm's clock, started with the take. A mocap clock offset puts the marker late against it.


def _take(name: str, tmp_path: Path) -> tuple[dict[str, Path], dict[str, object]]:
    made = materialise(scenario(name), tmp_path / "files")
    return made.files, made.truth


def test_an_arm_log_imported_with_its_take_drives_the_model_and_shows_the_clocks_agree(tmp_path: Path) -> None:
    files, truth = _take("mocap-clean-light-finger-deep-1", tmp_path)
    data = tmp_path / "data"
    result = import_mocap(files["take"], data, vacuum_kpa=float(truth["vacuum_kpa"]),  # type: ignore[arg-type]
                          arm_log=files["arm_log"])
    run = load_run(result.run_id, data)
    assert set(run.samples["source"]) == {"arm", "mocap"}
    assert run.samples.loc[run.samples["source"] == "arm", "trial_id"].nunique() == 24
    assert run.meta["arm_log"]["rate_hz"] == pytest.approx(125.0)
    batch = load_keystrokes([result.run_id], data).batch
    assert batch.arm_source == "arm"
    check = clock_check(batch)
    assert check is not None and not check.accepted and abs(check.value) < 1e-3


def test_a_mocap_clock_behind_the_arm_is_measured_on_the_arm_log_and_not_read_as_arm_lag(tmp_path: Path) -> None:
    """With the marker alone a 20 ms mocap offset reads exactly like a late arm; the arm log, on
    the arm's own clock, tells them apart: the clock is 20 ms behind, the arm is on time."""
    files, truth = _take("mocap-mocap_delay-offset-strong", tmp_path)
    data = tmp_path / "data"
    run_id = import_mocap(files["take"], data, vacuum_kpa=float(truth["vacuum_kpa"]),  # type: ignore[arg-type]
                          arm_log=files["arm_log"]).run_id
    batch = load_keystrokes([run_id], data, schedule=read_schedule(files["presses"])).batch
    clock = clock_check(batch)
    delay = truth["mocap_clock"]["delay_s"]  # type: ignore[index]
    assert clock is not None and clock.accepted and clock.value == pytest.approx(delay, abs=1e-3)
    lag = next(c for c in arm_checks(batch) if c.effect == "arm_lag")
    assert not lag.accepted, lag.text


def test_an_arm_log_started_apart_from_the_take_is_refused_with_the_start_to_give(tmp_path: Path) -> None:
    files, truth = _take("mocap-clean-stiff-key-hover-1", tmp_path)
    data = tmp_path / "data"
    first = read_arm_log(files["arm_log"]).first_timestamp_s
    with pytest.raises(InputError, match=r"1\.000 s apart") as caught:
        import_mocap(files["take"], data, arm_log=files["arm_log"], arm_log_start_s=first + 1.0)
    suggested = float(str(caught.value).split("--arm-log-start ")[1].split(" ")[0])
    assert suggested == pytest.approx(first, abs=2e-3)
    assert not list_runs(data)
    # Given that start, it imports.
    assert import_mocap(files["take"], data, arm_log=files["arm_log"], arm_log_start_s=suggested).trials == 24


def test_a_bad_arm_log_on_the_command_line_is_one_line_and_stores_nothing(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    files, _ = _take("mocap-clean-stiff-key-hover-1", tmp_path)
    data = tmp_path / "data"
    bad = tmp_path / "arm.csv"
    bad.write_text(files["take"].read_text()[:400], encoding="utf-8")  # a take given as the arm log
    code, _, err = invoke_cli(["import", "mocap", str(files["take"]), "--arm-log", str(bad), "--data", str(data)],
                              capsys, monkeypatch)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "arm.csv:1" in err and "not a UR arm log" in err
    assert not data.exists() or not list_runs(data)
    code, _, err = invoke_cli(["import", "mocap", str(files["take"]), "--arm-log", str(files["arm_log"]),
                               "--run", "some-run", "--data", str(data)], capsys, monkeypatch)
    assert code == 2 and "not both" in err


def _edited_log(files: dict[str, Path], tmp_path: Path, edit: str) -> Path:
    """The suite's arm log as a lab might have saved it wrongly."""
    import pandas as pd

    log = pd.read_csv(files["arm_log"])
    z = [c for c in log.columns if c.endswith("TCP_pose_2")]
    pose = [c for c in log.columns if "TCP_pose" in c]
    if edit == "millimetres":
        log[pose] = log[pose] * 1000.0
    elif edit == "z constant":  # the press along another pose column
        log[z] = log[z].iloc[0].to_numpy()
    elif edit == "z pointing down":
        log[z] = 2 * log[z].iloc[0].to_numpy() - log[z]
    elif edit == "milliseconds":
        log["timestamp"] = log["timestamp"] * 1000.0
    path = tmp_path / f"arm-{edit.replace(' ', '-')}.csv"
    log.to_csv(path, index=False)
    return path


@pytest.mark.parametrize(("edit", "said"), [
    ("millimetres", "is it in millimetres?"),
    ("z constant", "barely moves down"),
    ("z pointing down", "moves up where the take's arm marker moves down"),
    ("milliseconds", "timestamps in milliseconds"),
])
def test_an_arm_log_that_is_not_the_arm_the_marker_saw_is_refused(edit: str, said: str, tmp_path: Path) -> None:
    # Each used to be stored and to drive identify and discover with a wrong arm (a millimetre log:
    # a finger 1000x too far, k0/k1 at its bound, a 101 ms mocap clock "measured").
    files, truth = _take("mocap-clean-stiff-key-hover-1", tmp_path)
    data = tmp_path / "data"
    with pytest.raises(InputError, match=said):
        import_mocap(files["take"], data, arm_log=_edited_log(files, tmp_path, edit))
    assert not list_runs(data)


def test_an_arm_log_that_ends_early_is_imported_with_a_warning(tmp_path: Path) -> None:
    import pandas as pd

    files, _ = _take("mocap-clean-stiff-key-hover-1", tmp_path)
    log = pd.read_csv(files["arm_log"])
    short = tmp_path / "short.csv"
    log.iloc[: len(log) // 2].to_csv(short, index=False)
    result = import_mocap(files["take"], tmp_path / "data", arm_log=short)
    covered = result.extra["arm_log_keystrokes"]
    assert 0 < covered < result.trials
    assert any(f"covers {covered} of the take's {result.trials} keystrokes" in w for w in result.extra["warnings"])
    with pytest.raises(InputError, match="give --arm-log too"):
        import_mocap(files["take"], tmp_path / "data", arm_log_start_s=5000.0)
