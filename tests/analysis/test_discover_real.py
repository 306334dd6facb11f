"""Discovery on the real mocap take zzz40 (imported as a run): a report and a verdict."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from pianobot.cli import _register, app
from pianobot.io.importers import import_mocap


def test_discover_on_zzz40_gives_a_report_and_a_verdict(zhang2022: Path, tmp_path: Path) -> None:
    data = tmp_path / "data"
    run_id = import_mocap(zhang2022 / "zzz" / "zzz40.csv", data).run_id
    _register()
    report = tmp_path / "zzz40.html"
    result = CliRunner().invoke(
        app,
        [
            "discover",
            run_id,
            "--data",
            str(data),
            "--json",
            "--out",
            str(report),
            "--vacuum-kpa",
            "-40",
        ],
    )
    assert result.exit_code == 0, result.output
    payload = json.loads(result.stdout)
    assert payload["verdict"]
    assert payload["iterations"] and "candidates" in payload["iterations"][0]
    assert payload["notes"]  # the take records no depth/acceleration: the assumptions are stated
    assert report.is_file() and "Verdict" in report.read_text()


def test_missing_vacuum_is_a_one_line_input_error(zhang2022: Path, tmp_path: Path) -> None:
    data = tmp_path / "data"
    run_id = import_mocap(zhang2022 / "zzz" / "zzz40.csv", data).run_id
    _register()
    result = CliRunner().invoke(app, ["discover", run_id, "--data", str(data), "--json"])
    assert result.exit_code != 0
    assert "--vacuum-kpa" in str(result.exception) or "--vacuum-kpa" in result.output
