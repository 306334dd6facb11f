"""`pianobot identify | fit | report` end to end on stored synthetic runs."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "analysis"))
from _synthetic_runs import linear_keystrokes, sounded_trials, write_run  # noqa: E402

from pianobot.physics.msd import MSDParams  # noqa: E402


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "pianobot", *args], capture_output=True, text=True)


@pytest.fixture()
def traj_run(data_dir: Path) -> str:
    trials, samples = linear_keystrokes(MSDParams(), seed=0, speeds_mps=(0.02, 0.05))
    return write_run(data_dir, trials, samples)


def test_identify_json_has_parameters_with_intervals(data_dir: Path, traj_run: str, tmp_path: Path) -> None:
    out = tmp_path / "model.json"
    proc = _cli("identify", traj_run, "--data", str(data_dir), "--json", "--bootstrap", "3", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    payload = json.loads(proc.stdout)
    params = payload["parameters"]
    assert {"k2_npm", "c1_nspm", "c2_nspm", "k1_a_npm", "k1_npm@-40kPa"} <= set(params)
    assert params["k2_npm"]["ci95_lo"] <= params["k2_npm"]["value"] <= params["k2_npm"]["ci95_hi"]
    model = json.loads(out.read_text())
    assert model["schema"] == "pianobot.model/1"
    assert set(params) == set(model["intervals"])


def test_fit_json_prints_cv_table(data_dir: Path, tmp_path: Path) -> None:
    run = write_run(data_dir, sounded_trials(0), None)
    proc = _cli("fit", run, "--model", "poly", "--data", str(data_dir), "--json", "--out-dir", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    rows = {r["model"]: r for r in json.loads(proc.stdout)["cv"]}
    assert rows["poly"]["r2"] > rows["mean"]["r2"]
    assert (tmp_path / "predictor-poly.json").is_file()


def test_bad_input_one_line_exit_2(data_dir: Path, tmp_path: Path) -> None:
    no_mocap = write_run(data_dir, sounded_trials(0), None, name="nomocap")
    proc = _cli("identify", no_mocap, "--data", str(data_dir), "--out", str(tmp_path / "m.json"))
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "mocap" in proc.stderr
    proc = _cli("fit", "no-such-run", "--data", str(data_dir))
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    wrong = tmp_path / "wrong.json"
    wrong.write_text('{"schema": "other/1"}')
    proc = _cli("report", no_mocap, "--data", str(data_dir), "--model", str(wrong), "--out", str(tmp_path / "r.html"))
    assert proc.returncode == 2 and proc.stderr.startswith("error:") and proc.stderr.count("\n") == 1
