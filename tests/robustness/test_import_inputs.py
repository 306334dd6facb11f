"""Hostile files given to the importers: refused in one line, or read without the nonsense."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from pianobot.store import list_runs, load_run
from robustness.harness import assert_cli_refused, cli

FIXTURES = Path(__file__).resolve().parents[3] / "shared" / "fixtures" / "zhang2022"
LOG = FIXTURES / "data" / "soft" / "ctrl_midi" / "soft_60_angle_45.txt"
FORCE = FIXTURES / "data" / "soft" / "force" / "P60A45.txt"
TAKE = FIXTURES / "zzz" / "zzz40.csv"


@pytest.fixture()
def data(tmp_path: Path) -> Path:
    folder = tmp_path / "data"
    folder.mkdir()
    return folder


def _import(args: list[str | Path], data: Path, capsys: pytest.CaptureFixture[str],
            monkeypatch: pytest.MonkeyPatch) -> dict[str, object]:
    code, out, err = cli(["import", *args, "--data", data, "--json"], capsys, monkeypatch)
    assert code == 0, err
    result: dict[str, object] = json.loads(out)
    return result


def test_a_byte_order_mark_does_not_cost_the_first_record(zhang2022: Path, data: Path, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str],
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    with_bom = tmp_path / "bom.txt"
    with_bom.write_bytes(b"\xef\xbb\xbf" + LOG.read_bytes())
    plain = _import(["keystroke-log", LOG], data, capsys, monkeypatch)
    bom = _import(["keystroke-log", with_bom], data, capsys, monkeypatch)
    assert bom["trials"] == plain["trials"] == 135
    assert bom["skipped_lines"] == plain["skipped_lines"]
    first, second = (load_run(s.run_id, data).trials for s in list_runs(data))
    pd.testing.assert_series_equal(first["on_velocity"], second["on_velocity"])


@pytest.mark.parametrize("reading", ["9" * 100_000, "1" + "0" * 40], ids=["100000-digits", "1e40"])
def test_an_absurd_force_reading_is_a_skipped_line_not_a_force(
    reading: str, zhang2022: Path, data: Path, tmp_path: Path,
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    lines = FORCE.read_text().splitlines()
    middle = len(lines) // 2
    capture = tmp_path / "capture.txt"
    capture.write_text("\n".join([*lines[:middle], f"Analog reading = {reading}", *lines[middle:]]) + "\n")
    clean = _import(["force-log", FORCE], data, capsys, monkeypatch)
    hostile = _import(["force-log", capture], data, capsys, monkeypatch)
    assert hostile["trials"] == clean["trials"]
    skipped = hostile["skipped_lines"]
    assert isinstance(skipped, list) and [s["line"] for s in skipped] == [middle + 1]
    peaks = load_run(list_runs(data)[-1].run_id, data).trials["peak_force_n"]
    assert peaks.max() < 100.0  # newtons of a finger, not 3.5e38


def test_a_capture_without_presses_stores_no_run(data: Path, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str],
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    flat = tmp_path / "flat.txt"
    flat.write_text("Analog reading = 10\n" * 500)
    assert_cli_refused(["import", "force-log", flat, "--data", data], data, capsys, monkeypatch, "no press found")


def test_a_50_mb_line_is_not_a_motive_export(data: Path, tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str],
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    take = tmp_path / "oneline.csv"
    with open(take, "w") as handle:
        handle.write("Format Version,1.21,Take Name,x," + "A" * 50_000_000)
    assert_cli_refused(["import", "mocap", take, "--data", data], data, capsys, monkeypatch, str(take), "CSV")


def test_time_reversed_frames_are_refused(zhang2022: Path, data: Path, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str],
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    text = TAKE.read_text().splitlines()
    header = next(i for i, line in enumerate(text) if line.startswith("Frame,"))
    reversed_take = tmp_path / "reversed.csv"
    reversed_take.write_text("\n".join(text[: header + 1] + text[header + 1:][::-1]) + "\n")
    assert_cli_refused(["import", "mocap", reversed_take, "--data", data], data, capsys, monkeypatch,
            "time runs backwards", "time order")


@pytest.mark.parametrize("kind", ["keystroke-log", "force-log", "mocap"])
def test_an_import_of_a_folder_or_device_is_refused(kind: str, data: Path, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str],
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    assert_cli_refused(["import", kind, tmp_path, "--data", data], data, capsys, monkeypatch, "is a folder")
    if Path("/dev/zero").exists():
        assert_cli_refused(["import", kind, "/dev/zero", "--data", data], data, capsys, monkeypatch,
                "not a regular file")
