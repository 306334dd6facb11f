"""`pianobot fit RUN --model sequence` end to end on a log written the way the study's script did."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pianobot.analysis.sequence.files import load_sequence_model
from tests.cli_runner import invoke_cli
from tests.io.log_truth import Scenario, make_log


def _imported(tmp_path: Path, data: Path, capsys: pytest.CaptureFixture[str],
              monkeypatch: pytest.MonkeyPatch) -> str:
    log = tmp_path / "seq_log.txt"
    log.write_text(make_log(Scenario(n=96, layout="named", sound=0.95, seed=2)).text)
    code, out, err = invoke_cli(["import", "keystroke-log", str(log), "--data", str(data), "--json"], capsys, monkeypatch)
    assert code == 0, err
    return str(json.loads(out)["run_id"])


def test_fit_sequence_writes_a_table_by_context_and_a_model(
    tmp_path: Path, data_dir: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    run_id = _imported(tmp_path, data_dir, capsys, monkeypatch)
    models = tmp_path / "models"
    code, out, err = invoke_cli(["fit", run_id, "--data", str(data_dir), "--model", "sequence", "--context", "0,1",
                                 "--folds", "2", "--out-dir", str(models), "--json"], capsys, monkeypatch)
    assert code == 0, err
    payload = json.loads(out)
    names = [row["model"] for row in payload["cv"]]
    assert names == ["per-note gp", "sequence k=0", "sequence k=1"]
    # The log carries no sequence ids: the run is cut into stretches of 12 in play order.
    assert payload["n_sequences"] == 8 and payload["n_strokes"] >= 80
    assert all(row["on_velocity_rmse"] > 0 for row in payload["cv"])
    model = load_sequence_model(Path(payload["saved"]))
    assert model.k == payload["k"] in (0, 1)


def test_a_bad_context_is_one_line_and_exit_2(
    tmp_path: Path, data_dir: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    code, out, err = invoke_cli(["fit", "nosuchrun", "--data", str(data_dir), "--model", "sequence",
                                 "--context", "one,two"], capsys, monkeypatch)
    assert code == 2
    assert err.strip().count("\n") == 0 and "--context" in err
