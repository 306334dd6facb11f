"""`pianobot identify | fit | report` end to end on stored synthetic runs."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "analysis"))
from _synthetic_runs import linear_keystrokes, sounded_trials, write_run  # noqa: E402

from pianobot.cli import main  # noqa: E402
from pianobot.physics.msd import MSDParams  # noqa: E402
from pianobot.store import RunWriter  # noqa: E402


class _Result:
    def __init__(self, code: int, stdout: str, stderr: str) -> None:
        self.returncode, self.stdout, self.stderr = code, stdout, stderr


@pytest.fixture()
def cli(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> Callable[..., _Result]:
    """The real entry point in-process (a subprocess would pay the import time on every call)."""

    def run(*args: str) -> _Result:
        monkeypatch.setattr(sys, "argv", ["pianobot", *args])
        with pytest.raises(SystemExit) as stop:
            main()
        captured = capsys.readouterr()
        return _Result(int(stop.value.code or 0), captured.out, captured.err)

    return run


@pytest.fixture()
def traj_run(data_dir: Path) -> str:
    trials, samples = linear_keystrokes(MSDParams(), seed=0, speeds_mps=(0.02, 0.05))
    return write_run(data_dir, trials, samples)


def test_identify_json_has_parameters_with_intervals(cli: Callable[..., _Result], data_dir: Path, traj_run: str, tmp_path: Path) -> None:
    out = tmp_path / "model.json"
    proc = cli("identify", traj_run, "--data", str(data_dir), "--json", "--bootstrap", "3", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    payload = json.loads(proc.stdout)
    params = payload["parameters"]
    assert {"k2_npm", "c1_nspm", "c2_nspm", "k1_a_npm", "k1_npm@-40kPa"} <= set(params)
    assert params["k2_npm"]["ci95_lo"] <= params["k2_npm"]["value"] <= params["k2_npm"]["ci95_hi"]
    model = json.loads(out.read_text())
    assert model["schema"] == "pianobot.model/1"
    assert set(params) == set(model["intervals"])


def test_fit_json_prints_cv_table(cli: Callable[..., _Result], data_dir: Path, tmp_path: Path) -> None:
    run = write_run(data_dir, sounded_trials(0), None)
    proc = cli("fit", run, "--model", "poly", "--data", str(data_dir), "--json", "--out-dir", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    rows = {r["model"]: r for r in json.loads(proc.stdout)["cv"]}
    assert rows["poly"]["r2"] > rows["mean"]["r2"]
    assert (tmp_path / "predictor-poly.json").is_file()


def test_bad_input_one_line_exit_2(cli: Callable[..., _Result], data_dir: Path, tmp_path: Path) -> None:
    no_mocap = write_run(data_dir, sounded_trials(0), None, name="nomocap")
    proc = cli("identify", no_mocap, "--data", str(data_dir), "--out", str(tmp_path / "m.json"))
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "mocap" in proc.stderr
    proc = cli("fit", "no-such-run", "--data", str(data_dir))
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    wrong = tmp_path / "wrong.json"
    wrong.write_text('{"schema": "other/1"}')
    proc = cli("report", no_mocap, "--data", str(data_dir), "--model", str(wrong), "--out", str(tmp_path / "r.html"))
    assert proc.returncode == 2 and proc.stderr.startswith("error:") and proc.stderr.count("\n") == 1


def test_odd_options_are_refused_before_any_fitting(cli: Callable[..., _Result], data_dir: Path, traj_run: str,
                                                    tmp_path: Path) -> None:
    out = str(tmp_path / "m.json")
    (tmp_path / "m.json.taken").write_text("")
    for args, option, what in (
        (["identify", traj_run, "--seed", "-1", "--out", out], "--seed", "greater than or equal to 0"),
        (["identify", traj_run, "--x0-source", "banana", "--out", out], "--x0-source", "expected auto, arm"),
        (["identify", traj_run, "--vacuum-kpa", "-1e9", "--out", out], "--vacuum-kpa", "gauge pressure"),
        (["discover", traj_run, "--vacuum-kpa", "250"], "--vacuum-kpa", "gauge pressure"),
        (["identify", traj_run, "--out", "/proc/pianobot-model.json"], "--out", "cannot write in /proc"),
        # fit's folder used to be made after its cross-validation, failing in the system's words
        (["fit", traj_run, "--out-dir", str(tmp_path / "m.json.taken")], "--out-dir", "give a folder"),
        (["discover", traj_run, "--seed", "-1"], "--seed", "from 0 to 2**63 - 1"),
    ):
        proc = cli(*args, "--data", str(data_dir))
        assert proc.returncode == 2 and proc.stderr.count("\n") == 1, (args, proc.stderr)
        assert option in proc.stderr and what in proc.stderr, (args, proc.stderr)
    assert not Path(out).exists()


def test_a_run_given_twice_counts_once(cli: Callable[..., _Result], data_dir: Path, traj_run: str,
                                       tmp_path: Path) -> None:
    once = cli("identify", traj_run, "--data", str(data_dir), "--json", "--bootstrap", "0", "--out", str(tmp_path / "a.json"))
    twice = cli("identify", traj_run, traj_run[:-2], "--data", str(data_dir), "--json", "--bootstrap", "0",
                "--out", str(tmp_path / "b.json"))
    assert once.returncode == twice.returncode == 0, twice.stderr
    a, b = json.loads(once.stdout), json.loads(twice.stdout)
    assert {k: v["value"] for k, v in a["parameters"].items()} == {k: v["value"] for k, v in b["parameters"].items()}
    # fit (and report) counted it twice: every keystroke learnt twice, a better cross-validation.
    run = write_run(data_dir, sounded_trials(2), None)
    fits = [json.loads(cli("fit", *ids, "--model", "poly", "--data", str(data_dir), "--json",
                           "--out-dir", str(tmp_path / "m")).stdout)["cv"] for ids in ([run], [run, run[:-2]])]
    timing = ("latency_ms", "fit_s")
    assert [{k: v for k, v in row.items() if k not in timing} for row in fits[0]] == \
        [{k: v for k, v in row.items() if k not in timing} for row in fits[1]]


def test_fit_on_a_take_without_midi_says_so(cli: Callable[..., _Result], data_dir: Path, traj_run: str) -> None:
    proc = cli("fit", traj_run, "--data", str(data_dir))
    assert proc.returncode == 2 and "no keystroke has a MIDI outcome" in proc.stderr, proc.stderr


def test_report_compare_on_a_silent_run_still_writes_the_report(cli: Callable[..., _Result], data_dir: Path,
                                                                  tmp_path: Path) -> None:
    silent = sounded_trials(0).assign(status="silent", on_velocity=float("nan"), midi_hold_s=float("nan"), n_note_on=0)
    run = write_run(data_dir, silent, None, name="silent")
    out = tmp_path / "r.html"
    proc = cli("report", run, "--compare", "--data", str(data_dir), "--out", str(out), "--no-progress")
    assert proc.returncode == 0 and out.is_file(), proc.stderr
    assert "warning: --compare: no model comparison (every keystroke is silent" in proc.stderr


def test_empty_run_is_one_line_error(cli: Callable[..., _Result], data_dir: Path, tmp_path: Path) -> None:
    writer = RunWriter.create(data_dir, name="empty", kind="import", meta={}, plan=None, fsync=False)
    writer.finish("completed")
    for command in (["report", writer.run_id, "--out", str(tmp_path / "r.html")],
                    ["identify", writer.run_id, "--out", str(tmp_path / "m.json")],
                    ["fit", writer.run_id, "--out-dir", str(tmp_path)]):
        proc = cli(*command, "--data", str(data_dir))
        assert proc.returncode == 2, (command, proc.stderr)
        assert proc.stderr.startswith("error:") and proc.stderr.count("\n") == 1 and "no trials" in proc.stderr
    assert not (tmp_path / "r.html").exists() and not (tmp_path / "m.json").exists()


def test_identify_warns_on_implausible_keys_and_stores_the_warnings(
        cli: Callable[..., _Result], data_dir: Path, tmp_path: Path) -> None:
    # A key damped past resonance, a finger that softens with vacuum, two keystrokes per level.
    odd = MSDParams(c2_nspm=40.0, k1_a_npm=200.0, k1_b_npm_per_kpa=-1.5)
    trials, samples = linear_keystrokes(odd, seed=2, levels_kpa=(-20.0, -80.0), speeds_mps=(0.02, 0.05))
    run = write_run(data_dir, trials, samples, name="odd")
    out, plot = tmp_path / "model.json", tmp_path / "identified.png"
    proc = cli("identify", run, "--data", str(data_dir), "--bootstrap", "3", "--out", str(out), "--plot", str(plot))
    assert proc.returncode == 0, proc.stderr
    warnings = [line for line in proc.stderr.splitlines() if line.startswith("warning: ")]
    stored = json.loads(out.read_text())["warnings"]
    assert {"no_resonance", "stiffness_slope", "few_keystrokes"} <= {w["check"] for w in stored}
    assert len(warnings) == len(stored) and all("likely cause" in w for w in warnings)
    assert any("falls with vacuum" in w for w in warnings)
    assert "none (largest at 0 Hz)" in proc.stdout and "0.00 Hz" not in proc.stdout
    assert f"figure written to {plot}" in " ".join(proc.stdout.split()) and plot.stat().st_size > 10_000
    # The study's own keys, five speeds at each of two levels: nothing to warn about.
    trials, samples = linear_keystrokes(MSDParams(), seed=3, speeds_mps=(0.015, 0.025, 0.035, 0.045, 0.055),
                                        levels_kpa=(-20.0, -80.0))
    plain = write_run(data_dir, trials, samples, name="plain")
    proc = cli("identify", plain, "--data", str(data_dir), "--bootstrap", "3", "--out", str(out), "--json")
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["warnings"] == json.loads(out.read_text())["warnings"] == []


def test_an_analysis_says_when_its_run_is_unfinished(cli: Callable[..., _Result], data_dir: Path, tmp_path: Path) -> None:
    import pandas as pd

    from pianobot.store import RunLock

    trials = sounded_trials(0)
    planned = [*trials["trial_id"], *(f"later-{i}" for i in range(20))]
    plan = pd.DataFrame({"trial_id": planned, "index": range(len(planned))})
    writer = RunWriter.create(data_dir, name="partial", kind="sweep", meta={"seed": 0}, plan=plan, fsync=False)
    writer.append(trials)
    writer.close()  # what a kill -9 leaves: status 'running', no live lock
    report = ("report", writer.run_id, "--data", str(data_dir), "--out", str(tmp_path / "r.html"), "--no-progress")
    proc = cli(*report)
    assert proc.returncode == 0, proc.stderr
    assert f"run {writer.run_id} did not finish" in proc.stderr
    assert f"{len(trials)} of {len(trials) + 20} planned keystrokes are analysed" in proc.stderr
    assert f"pianobot sweep --resume {writer.run_id}" in proc.stderr
    assert f"run {writer.run_id} did not finish" in (tmp_path / "r.html").read_text()  # the page says it too
    # Still being recorded: a live process holds its lock.
    with RunLock(writer.paths.lock, purpose="sweep"):
        proc = cli(*report)
    assert "is still running (pid" in proc.stderr and "(sweep)" in proc.stderr
    # Stopped early, and said why.
    RunWriter.reopen(data_dir, writer.run_id, fsync=False).finish("stopped", reason="stop requested (Ctrl-C)")
    proc = cli(*report)
    assert f"run {writer.run_id} stopped (stop requested (Ctrl-C)) after {len(trials)} of" in proc.stderr
    # A finished run gets no such warning.
    done = write_run(data_dir, trials, None)
    assert "warning" not in cli("report", done, "--data", str(data_dir), "--out", str(tmp_path / "d.html"),
                                "--no-progress").stderr
