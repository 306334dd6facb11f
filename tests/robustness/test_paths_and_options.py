"""Paths and options: a file for a folder, read-only folders, impossible numbers, output paths.

Each is one line on stderr and exit 2, before anything is stored or computed.
"""

from __future__ import annotations

import os
import shutil
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from robustness.harness import (
    QUICKSTART,
    as_unprivileged,
    assert_cli_refused,
    assert_refused,
    only_run,
    unchanged,
)

FIXTURES = Path(__file__).resolve().parents[3] / "shared" / "fixtures" / "zhang2022"
LOG_LINE = "{'control': [60, 45, 0.5, 0.03, 0.04, 0.05, 0], 'midi': [[[144, 57, 1, 0], 468620]]}\n"


@pytest.mark.parametrize("command", ["sweep", "resume", "import"])
def test_data_that_is_a_file_is_refused(command: str, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                        monkeypatch: pytest.MonkeyPatch) -> None:
    not_a_folder = tmp_path / "data"
    not_a_folder.write_text("I am a file")
    log = tmp_path / "log.txt"
    log.write_text(LOG_LINE)
    args = {
        "sweep": ["sweep", QUICKSTART],
        "resume": ["sweep", "--resume", "20260101-000000-x-0000"],
        "import": ["import", "keystroke-log", log],
    }[command]
    assert_cli_refused([*args, "--data", not_a_folder], tmp_path, capsys, monkeypatch, "is a file, not a folder")


@pytest.fixture()
def shared_dir() -> Iterator[Path]:
    """A folder an unprivileged user can enter (pytest's own tmp is private to its user)."""
    root = Path(tempfile.mkdtemp(prefix="pianobot-ro-"))
    root.chmod(0o755)
    try:
        yield root
    finally:
        for path in [root, *root.rglob("*")]:
            if path.is_dir():
                path.chmod(0o755)
        shutil.rmtree(root, ignore_errors=True)


def _read_only(folder: Path) -> None:
    for path in [folder, *folder.rglob("*")]:
        mode = path.stat().st_mode
        path.chmod(stat.S_IMODE(mode) & ~0o222 | (0o555 if path.is_dir() else 0o444))


@pytest.mark.parametrize("command", ["sweep", "resume", "import"])
def test_a_read_only_data_folder_is_refused_in_one_line(command: str, shared_dir: Path,
                                                        killed_run: Path) -> None:
    data = shared_dir / "data"
    shutil.copytree(killed_run, data)
    spec = shared_dir / "quickstart.yaml"
    shutil.copy(QUICKSTART, spec)
    log = shared_dir / "log.txt"
    log.write_text(LOG_LINE)
    _read_only(data)
    args = {
        "sweep": ["sweep", str(spec)],
        "resume": ["sweep", "--resume", only_run(data).name],
        "import": ["import", "keystroke-log", str(log)],
    }[command]
    with unchanged(data):
        code, _, err = as_unprivileged([*args, "--data", str(data)])
    line = assert_refused(code, err)
    assert "writ" in line or "read-only" in line or "Permission denied" in line, line


@pytest.mark.parametrize("seed", ["-5", "x", "1e3", str(2**64)])
def test_a_bad_seed_stores_no_run(seed: str, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                  monkeypatch: pytest.MonkeyPatch) -> None:
    data = tmp_path / "data"
    data.mkdir()
    assert_cli_refused(["sweep", QUICKSTART, "--seed", seed, "--data", data], data, capsys, monkeypatch, "--seed")
    assert not (data / "runs").exists()


@pytest.mark.parametrize(("args", "option"), [
    (["model", "bode", "--vacuum-kpa", "nan"], "--vacuum-kpa"),
    (["model", "simulate", "--down-velocity-mps", "inf"], "--down-velocity-mps"),
    (["model", "simulate", "--depth-m=-inf"], "--depth-m"),
    (["import", "force-log", "{log}", "--gain-n", "nan"], "--gain-n"),
    (["import", "force-log", "{log}", "--rate-hz", "1e999"], "--rate-hz"),
    (["import", "mocap", "{log}", "--min-coverage", "nan"], "--min-coverage"),
    (["identify", "x", "--vacuum-kpa", "NaN"], "--vacuum-kpa"),
])
def test_a_non_finite_number_option_is_refused(args: list[str], option: str, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str],
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    data = tmp_path / "data"
    data.mkdir()
    log = tmp_path / "capture.txt"
    log.write_text("Analog reading = 10\n" * 100)
    full = [a.replace("{log}", str(log)) for a in args]
    assert_cli_refused([*full, "--data", data], data, capsys, monkeypatch, option, "finite")


def test_a_min_coverage_outside_0_1_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    data = tmp_path / "data"
    data.mkdir()
    take = tmp_path / "take.csv"
    take.write_text("Format Version,1.21\n")
    assert_cli_refused(["import", "mocap", take, "--min-coverage", "1.5", "--data", data], data, capsys, monkeypatch,
            "--min-coverage", "[0, 1]")


@pytest.mark.parametrize("command", ["identify", "report"])
def test_an_output_that_is_a_folder_is_refused_before_the_work(
    command: str, completed_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    folder = tmp_path / "out"
    folder.mkdir()
    run = only_run(completed_run).name
    with unchanged(tmp_path):
        from robustness.harness import cli

        code, _, err = cli([command, run, "--data", completed_run, "--out", folder], capsys, monkeypatch)
    assert_refused(code, err, "--out", "is a folder")
    assert sorted(os.listdir(tmp_path)) == ["data", "out"] and os.listdir(folder) == []


def test_the_model_writer_leaves_nothing_when_it_cannot_write(tmp_path: Path) -> None:
    from pianobot.errors import InputError
    from pianobot.physics.model import KeystrokeModel, save_model

    target = tmp_path / "model.json"
    target.mkdir()
    with pytest.raises(InputError, match="is a folder"):
        save_model(KeystrokeModel.study(), target)
    assert os.listdir(tmp_path) == ["model.json"] and os.listdir(target) == []


def test_usage_errors_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                   monkeypatch: pytest.MonkeyPatch) -> None:
    data = tmp_path / "data"
    data.mkdir()
    assert_cli_refused(["sweep", QUICKSTART, "--bogus", "--data", data], data, capsys, monkeypatch, "--bogus")
    assert_cli_refused(["no-such-command", "--data", data], data, capsys, monkeypatch, "no-such-command")
    assert_cli_refused(["runs", "show", "--data", data], data, capsys, monkeypatch, "Missing argument")
