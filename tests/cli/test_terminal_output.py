"""What a researcher sees on an 80-column terminal: help pages, tables, where files went."""

from __future__ import annotations

import io
import json
import re
from pathlib import Path

import pytest
import typer
from cli_runner import invoke_cli as cli
from rich.console import Console

import pianobot.cli as cli_package
from pianobot.cli.common import Column, fit_columns, print_table
from pianobot.run import run_sweep

ROOT = Path(__file__).resolve().parents[2]
SONGS = ROOT / "experiments" / "songs"


def _lines_fit(text: str, width: int = 80) -> None:
    """Every line fits, except a lone path or id longer than the terminal (kept whole)."""
    for line in text.splitlines():
        if " " not in line.strip():
            continue
        assert len(line.rstrip()) <= width, f"{len(line.rstrip())} > {width}: {line!r}"
    assert "…" not in text, f"something was cut:\n{text}"


@pytest.fixture(scope="module")
def sweep_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    data = tmp_path_factory.mktemp("data")
    outcome = run_sweep(ROOT / "experiments" / "quickstart.yaml", data_dir=data, progress=False)
    return data, outcome.run_id


def _command_paths() -> list[list[str]]:
    cli_package._register(None)
    root = typer.main.get_command(cli_package.app)
    paths: list[list[str]] = []

    def walk(command: object, path: list[str]) -> None:
        paths.append(path)
        for name, sub in getattr(command, "commands", {}).items():
            walk(sub, [*path, name])

    walk(root, [])
    return paths


def test_every_help_page_fits_80_columns_and_shows_flags_as_flags(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "80")
    paths = _command_paths()
    assert ["fit"] in paths and ["runs", "show"] in paths and ["import", "mocap"] in paths
    for path in paths:
        code, out, err = cli([*path, "--help"], capsys, monkeypatch)
        assert code == 0, (path, err)
        assert "<bool>" not in out, f"pianobot {' '.join(path)} --help shows a flag as taking a value"
        _lines_fit(out)
    code, out, _ = cli(["sweep", "--help"], capsys, monkeypatch)
    assert re.search(r"--json\s+Machine-readable", out), out


@pytest.mark.parametrize("args", [["runs", "--json", "true"], ["fit", "some-run", "--json", "True"],
                                  ["play", "song.mid", "--dry-run", "no"]])
def test_a_value_after_a_flag_is_one_clear_error(args: list[str], capsys: pytest.CaptureFixture[str],
                                                 monkeypatch: pytest.MonkeyPatch, data_dir: Path) -> None:
    code, out, err = cli([*args, "--data", str(data_dir)], capsys, monkeypatch)
    flag = args[-2]
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith(f"error: {flag} is a flag"), err
    assert not (data_dir / "runs").exists()


def test_fit_table_fits_80_columns_and_names_the_saved_files(
        sweep_run: tuple[Path, str], tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    data, run_id = sweep_run
    monkeypatch.setenv("COLUMNS", "80")
    code, out, err = cli(["fit", run_id, "--data", str(data), "--model", "poly", "--model", "spline",
                          "--out-dir", str(tmp_path / "models")], capsys, monkeypatch)
    assert code == 0, err
    _lines_fit(out)
    assert "mean (baseline)" in out and "poly" in out and "spline" in out
    assert re.search(r"R²", out) and "(MIDI)" in out  # headings carry units
    written = " ".join(out.split())  # the path may wrap
    for kind in ("poly", "spline"):
        path = tmp_path / "models" / f"predictor-{kind}.json"
        assert path.is_file()
        assert f"predictor {kind} written to" in written and f"predictor-{kind}.json" in written
    # The same command piped to a program (no COLUMNS) keeps every column on one line per row.
    monkeypatch.delenv("COLUMNS")
    code, out, _ = cli(["fit", run_id, "--data", str(data), "--model", "poly", "--out-dir",
                        str(tmp_path / "models")], capsys, monkeypatch)
    assert code == 0 and "predict (ms)" in out and "not shown" not in out


def test_play_dry_run_table_fits_80_columns(capsys: pytest.CaptureFixture[str],
                                            monkeypatch: pytest.MonkeyPatch, data_dir: Path) -> None:
    monkeypatch.setenv("COLUMNS", "80")
    code, out, err = cli(["play", str(SONGS / "twinkle.mid"), "--dry-run", "--data", str(data_dir)],
                         capsys, monkeypatch)
    assert code == 0, err
    _lines_fit(out)
    header = out.split("─")[0]
    for heading in ("pitch", "onset", "status"):
        assert heading in header
    # Every planned note has its row: the first cell of each row is the note, counted from 1.
    indices = [int(m) for m in re.findall(r"^\s*(\d+)\s+\d+\s", out, flags=re.M)]
    assert indices and indices == list(range(1, len(indices) + 1))


def test_columns_are_dropped_lowest_priority_first_and_numbers_are_never_cut() -> None:
    columns = [Column("id"), Column("value (mm)", justify="right"), Column("note", 2, wrap=True),
               Column("extra", 1, "right"), Column("detail", 3)]
    rows = [["20261124-000000-name-abcd", "12.345", "a long explanation " * 3, "7", "x" * 30]]
    kept, widths = fit_columns(columns, rows, 200)
    assert kept == [0, 1, 2, 3, 4]
    kept, widths = fit_columns(columns, rows, 80)
    assert kept == [0, 1, 2, 3]  # `detail` (priority 3) goes first
    assert widths[0] == len(rows[0][0]) and widths[1] >= len("12.345")
    assert sum(widths) + 3 * (len(kept) - 1) <= 80
    kept, _ = fit_columns(columns, rows, 60)
    assert kept == [0, 1, 3]  # then the prose column (priority 2), before `extra` (1)
    kept, widths = fit_columns(columns, rows, 20)  # nothing left to drop: fold rather than cut
    assert kept == [0, 1] and widths == [len(rows[0][0]), len("12.345")]
    buffer = Console(width=60, record=True, file=io.StringIO())
    dropped = print_table(columns, rows, console=buffer)
    text = buffer.export_text()
    assert dropped == ["note", "detail"]
    assert "20261124-000000-name-abcd" in text and "12.345" in text
    assert "not shown at 60 columns: note, detail" in " ".join(text.split())


def test_commands_that_write_a_file_say_where(capsys: pytest.CaptureFixture[str],
                                              monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    for args in (["model", "bode"], ["model", "simulate"]):
        png = tmp_path / f"{args[1]}.png"
        code, out, err = cli([*args, "--plot", str(png)], capsys, monkeypatch)
        assert code == 0, err
        assert png.is_file() and f"figure written to {png}" in " ".join(out.split())
        code, out, _ = cli([*args, "--plot", str(png), "--json"], capsys, monkeypatch)
        assert json.loads(out)["plot"] == str(png)


def test_help_paragraphs_are_reflowed_not_cut_at_the_source_line_breaks(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    from pianobot.cli.common import reflow

    assert reflow("One line\n\nA paragraph wrapped\nat 100 columns.\n\n- a list\n- stays") == (
        "One line\n\nA paragraph wrapped at 100 columns.\n\n- a list\n- stays")
    monkeypatch.setenv("COLUMNS", "80")
    code, out, _ = cli(["import", "mocap", "--help"], capsys, monkeypatch)
    assert code == 0
    # The docstring's second paragraph breaks after "when" in the source: the terminal wraps it.
    text = " ".join(out.split())
    assert "inferred only when the evidence is clear" in text
    lines = [line.strip() for line in out.splitlines()]
    assert not any(0 < len(line) < 25 and line.endswith("when") for line in lines)
