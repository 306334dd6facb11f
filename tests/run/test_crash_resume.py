"""Crash test: kill -9 a sweep subprocess at several points, resume each time, lose nothing.

The final trials table must hold every planned trial exactly once and equal, trial by trial, an
uninterrupted run with the same seed; samples and MIDI must not be duplicated either.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from pianobot.run import run_sweep
from pianobot.store import load_run, read_journal
from pianobot.store.journal import BOOKKEEPING_EVENTS

OUTCOME = ["trial_id", "index", "status", "note", "vacuum_kpa", "down_velocity_mps", "depth_m",
           "on_velocity", "off_velocity", "t_on_s", "t_off_s", "midi_hold_s", "n_note_on",
           "key_speed_at_trigger_mps", "max_key_travel_m"]

SPEC = """\
name: crash-test
rig: sim
finger: soft
note: 57
sweep:
  mode: grid
  params:
    vacuum_kpa: [0, -30, -60]
    down_velocity_mps: [0.015, 0.03, 0.045, 0.06]
    depth_m: [0.02, 0.03, 0.035]
  fixed: {acceleration_mps2: 0.5, distance_m: 0.02, hold_s: 0.0}
  order: blocked-shuffle
  seed: 11
record: [midi, arm, mocap]
"""
SEED = 3
KILLS = 5


def _journal_lines(path: Path) -> int:
    """Lines of the runner's events (the store's bookkeeping records are not kill points)."""
    try:
        with open(path, "rb") as handle:
            lines = handle.read().split(b"\n")[:-1]
    except FileNotFoundError:
        return 0
    bookkeeping = tuple(f'"event":"{e}"'.encode() for e in BOOKKEEPING_EVENTS)
    return sum(1 for line in lines if not any(tag in line for tag in bookkeeping))


# The `sweep` command exactly as `python -m pianobot sweep` runs it, without importing every
# other command group first (analysis pulls in scikit-learn: seconds per start on a busy CI box).
SWEEP_ONLY = (
    "import sys, typer\n"
    "from pianobot.cli.common import print_error\n"
    "from pianobot.cli.sweep import register\n"
    "from pianobot.errors import InputError\n"
    "app = typer.Typer(pretty_exceptions_enable=False)\n"
    "app.callback()(lambda: None)  # a group, so `sweep` is a command name, as in pianobot\n"
    "register(app)\n"
    "try:\n"
    "    app()\n"
    "except InputError as exc:\n"
    "    print_error(str(exc)); sys.exit(2)\n"
)


def _start(spec: Path, data_dir: Path, resume: str | None) -> subprocess.Popen[bytes]:
    args = [sys.executable, "-c", SWEEP_ONLY, "sweep", str(spec), "--data", str(data_dir),
            "--json", "--no-progress", "--batch-trials", "2", "--seed", str(SEED)]
    if resume is not None:
        args += ["--resume", resume]
    return subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def _run_folder(data_dir: Path) -> Path | None:
    runs = sorted((data_dir / "runs").glob("*")) if (data_dir / "runs").is_dir() else []
    return runs[0] if runs else None


def _kill_after(process: subprocess.Popen[bytes], data_dir: Path, extra_lines: int, start_lines: int) -> bool:
    """SIGKILL the sweep once its journal has grown by `extra_lines`; False if it ended first."""
    while process.poll() is None:
        folder = _run_folder(data_dir)
        if folder is not None and _journal_lines(folder / "journal.jsonl") >= start_lines + extra_lines:
            process.send_signal(signal.SIGKILL)
            process.wait()  # reap it, so its run.lock is seen as stale
            return True
        time.sleep(0.0005)
    return False


@pytest.mark.slow
def test_kill_9_at_five_points_and_resume_loses_and_duplicates_nothing(tmp_path: Path) -> None:
    spec = tmp_path / "crash.yaml"
    spec.write_text(SPEC)
    reference_dir = tmp_path / "reference"
    reference = run_sweep(spec, data_dir=reference_dir, seed=SEED, progress=False)
    assert reference.status == "completed" and reference.trials == 36
    expected = load_run(reference.run_id, reference_dir)

    data_dir = tmp_path / "data"
    kills = 0
    run_id: str | None = None
    # Kill points: journal growth after each (re)start — mid-trial, right after a part, ...
    for extra in (4, 7, 3, 9, 5, 6, 8, 4, 11, 6):
        folder = _run_folder(data_dir)
        start = _journal_lines(folder / "journal.jsonl") if folder is not None else 0
        process = _start(spec, data_dir, run_id)
        killed = _kill_after(process, data_dir, extra, start)
        folder = _run_folder(data_dir)
        assert folder is not None
        run_id = folder.name
        if killed:
            kills += 1
            assert process.returncode == -signal.SIGKILL
            assert load_run(run_id, data_dir).meta["status"] == "running"
        else:
            out, err = process.communicate()
            assert process.returncode == 0, err.decode()
            break
        if kills >= KILLS:
            break
    assert kills >= KILLS, f"only {kills} kills landed before the sweep finished"

    if load_run(run_id, data_dir).meta["status"] != "completed":
        process = _start(spec, data_dir, run_id)
        out, err = process.communicate(timeout=600)
        assert process.returncode == 0, err.decode()
        assert json.loads(out)["status"] == "completed"

    run = load_run(run_id, data_dir)
    trials = run.trials
    assert sorted(trials["trial_id"]) == sorted(run.plan["trial_id"])
    assert trials["trial_id"].is_unique and len(trials) == 36
    a = trials.sort_values("trial_id")[OUTCOME].reset_index(drop=True)
    b = expected.trials.sort_values("trial_id")[OUTCOME].reset_index(drop=True)
    pd.testing.assert_frame_equal(a, b, check_exact=False, rtol=1e-9, atol=1e-12)

    # No duplicated samples or MIDI: per trial and source, the same counts as the reference.
    def counts(frame: pd.DataFrame, keys: list[str]) -> pd.Series:
        return frame.groupby(keys).size().sort_index()

    pd.testing.assert_series_equal(
        counts(run.samples, ["trial_id", "source"]), counts(expected.samples, ["trial_id", "source"])
    )
    pd.testing.assert_series_equal(counts(run.midi, ["trial_id"]), counts(expected.midi, ["trial_id"]))

    meta = run.meta
    assert [i["kind"] for i in meta["interruptions"]].count("crash") >= KILLS
    assert meta["sessions"] >= KILLS + 1
    journal = read_journal(run.path / "journal.jsonl")
    done = {e["trial_id"] for e in journal if e["event"] in ("done", "recovered")}
    assert done == set(trials["trial_id"])
    assert not list((run.path / "parts").iterdir())
    assert not (run.path / "run.lock").exists()
    assert os.listdir(run.path) and all(not name.startswith(".") for name in os.listdir(run.path))


@pytest.mark.slow
def test_sigterm_finishes_the_trial_marks_the_run_interrupted_and_resume_completes(tmp_path: Path) -> None:
    spec = tmp_path / "crash.yaml"
    spec.write_text(SPEC)
    data_dir = tmp_path / "data"
    process = _start(spec, data_dir, None)
    while process.poll() is None:
        folder = _run_folder(data_dir)
        if folder is not None and _journal_lines(folder / "journal.jsonl") >= 6:
            process.send_signal(signal.SIGTERM)
            break
        time.sleep(0.0005)
    out, err = process.communicate(timeout=600)
    if process.returncode == 0:
        pytest.skip("the sweep finished before the signal landed")  # a very fast machine
    assert process.returncode == 130, err.decode()
    result = json.loads(out)
    assert result["status"] == "interrupted" and "SIGTERM" in result["reason"]
    run = load_run(result["run_id"], data_dir)
    journal = run.journal
    started = [e["trial_id"] for e in journal if e["event"] == "started"]
    done = [e["trial_id"] for e in journal if e["event"] == "done"]
    assert started == done  # the trial in flight was finished, not abandoned
    assert run.meta["interruptions"][0]["kind"] == "signal"
    process = _start(spec, data_dir, result["run_id"])
    out, err = process.communicate(timeout=600)
    assert process.returncode == 0, err.decode()
    final = load_run(result["run_id"], data_dir).trials
    assert len(final) == 36 and final["trial_id"].is_unique
