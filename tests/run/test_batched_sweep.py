"""Batched simulated sweeps: blocks of trials simulated together, the same data as one by one.

The simulated rig works out a block of keystrokes ahead (their physics in one vectorised batch);
every keystroke still runs through the same station, faults and retries, and the block lands as
one part. So the data must equal the one-at-a-time path exactly, faults included, and a kill -9
in the middle of a block must lose and duplicate nothing.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from pianobot.rig import Rig
from pianobot.run import BlockEnded, RunStarted, TrialDone, run_sweep
from pianobot.store import load_run
from tests.run.test_crash_resume import SWEEP_ONLY, _journal_lines, _run_folder

REPO = Path(__file__).resolve().parents[2]
FAULTY_RIG = """\
kind: sim
seed: 5
world: {preset: default}
faults:
  drop_connection_every_n_presses: 9
  midi_loss_prob: 0.05
  mocap_drop_prob: 0.05
retry: {max_attempts: 3, backoff_s: 0.5, backoff_factor: 2.0}
"""
SPEC = """\
name: batched
rig: rig.yaml
finger: soft
note: 57
sweep:
  mode: random
  samples: {samples}
  seed: 4
  params:
    vacuum_kpa: [0, -40, -80]
    down_velocity_mps: {{low: 0.02, high: 0.06}}
    acceleration_mps2: {{low: 0.3, high: 1.0}}
    depth_m: {{low: 0.02, high: 0.035}}
  fixed: {{distance_m: 0.01, hold_s: 0.0}}
  order: blocked-shuffle
  block_by: [vacuum_kpa]
{approach}record: [midi, arm, mocap]
"""
OUTCOME = ["trial_id", "index", "attempt", "status", "vacuum_kpa", "down_velocity_mps", "depth_m",
           "t_start_s", "on_velocity", "off_velocity", "t_on_s", "t_off_s", "midi_hold_s",
           "n_note_on", "key_speed_at_trigger_mps", "max_key_travel_m"]


def _spec(folder: Path, samples: int, approach: str = "") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "rig.yaml").write_text(FAULTY_RIG)
    path = folder / "batched.yaml"
    path.write_text(SPEC.format(samples=samples, approach=approach))
    return path


def _same_data(a: Path, b: Path, data_a: Path, data_b: Path) -> None:
    run_a, run_b = load_run(a.name, data_a), load_run(b.name, data_b)
    x = run_a.trials.sort_values("trial_id")[OUTCOME].reset_index(drop=True)
    y = run_b.trials.sort_values("trial_id")[OUTCOME].reset_index(drop=True)
    pd.testing.assert_frame_equal(x, y, check_exact=True)
    for table in ("samples", "midi"):
        keys = ["trial_id", "source", "t_s"] if table == "samples" else ["trial_id", "t_s", "type"]
        u = getattr(run_a, table).drop(columns="run_id").sort_values(keys).reset_index(drop=True)
        v = getattr(run_b, table).drop(columns="run_id").sort_values(keys).reset_index(drop=True)
        pd.testing.assert_frame_equal(u, v, check_exact=True)


@pytest.mark.parametrize("approach", ["", "approach: fast\n"], ids=["as-specified", "fast"])
def test_blocks_give_exactly_the_one_at_a_time_data_faults_included(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, approach: str
) -> None:
    spec = _spec(tmp_path, 40, approach)
    records: list[object] = []
    blocked = run_sweep(spec, data_dir=tmp_path / "blocked", progress=False, batch_trials=16,
                        subscribers=[records.append])
    assert [r.blocks for r in records if isinstance(r, RunStarted)] == [True]
    ends = [r for r in records if isinstance(r, BlockEnded)]
    # The keys whose note-on the link lost are pressed again once the plan has run, in blocks too.
    lost = [r.data for r in records if isinstance(r, TrialDone) and r.data.note_on_lost]
    assert lost and all(not (d.samples or d.midi) for d in lost)  # kept with the redone keystroke
    assert [e.trials for e in ends][:3] == [16, 16, 8]
    assert sum(e.trials for e in ends[3:]) == len(lost)
    assert sum(isinstance(r, TrialDone) for r in records) == 40 + len(lost)
    # One part per block: the journal's done lines name one part per block.
    run = load_run(blocked.run_id, tmp_path / "blocked")
    assert len({e["part"] for e in run.journal if e["event"] == "done"}) == len(ends)
    retried = [e for e in run.journal if e["event"] == "retried"]
    assert len(retried) >= 3 and (run.trials["attempt"] - 1).sum() == len(retried)
    assert set(run.trials.set_index("trial_id").loc[[d.trial_id for d in lost], "status"]) <= {"ok", "silent"}
    assert not run.samples.duplicated(["trial_id", "source", "t_s"]).any()

    monkeypatch.setattr(Rig, "batches", property(lambda self: False))
    single = run_sweep(spec, data_dir=tmp_path / "single", progress=False, batch_trials=16)
    assert single.lab_time_s == pytest.approx(blocked.lab_time_s, abs=1e-9)
    _same_data(blocked.path, single.path, tmp_path / "blocked", tmp_path / "single")


CLEAN_FAULTS = FAULTY_RIG.replace("  drop_connection_every_n_presses: 9\n", "")


@pytest.mark.slow
def test_kill_9_inside_blocks_and_resume_loses_and_duplicates_nothing(tmp_path: Path) -> None:
    spec = _spec(tmp_path, 150)
    (tmp_path / "rig.yaml").write_text(CLEAN_FAULTS)  # MIDI and mocap losses, keyed per trial
    reference = run_sweep(spec, data_dir=tmp_path / "reference", progress=False, seed=3)
    data_dir = tmp_path / "data"
    run_id: str | None = None
    kills = 0
    # 150 trials in blocks of 128: kill inside the first block (nothing stored yet), inside the
    # second, and again after resuming.
    for extra in (40, 60, 30, 45):
        folder = _run_folder(data_dir)
        start = _journal_lines(folder / "journal.jsonl") if folder is not None else 0
        process = _start_blocks(spec, data_dir, run_id)
        while process.poll() is None:
            folder = _run_folder(data_dir)
            if folder is not None and _journal_lines(folder / "journal.jsonl") >= start + extra:
                process.send_signal(signal.SIGKILL)
                process.wait()
                kills += 1
                break
            time.sleep(0.0005)
        else:
            _, err = process.communicate()
            assert process.returncode == 0, err.decode()
        folder = _run_folder(data_dir)
        assert folder is not None
        run_id = folder.name
        if load_run(run_id, data_dir).meta["status"] != "running":
            break
    assert kills >= 2
    if load_run(run_id, data_dir).meta["status"] == "running":
        process = _start_blocks(spec, data_dir, run_id)
        _, err = process.communicate(timeout=600)
        assert process.returncode == 0, err.decode()
    run = load_run(run_id, data_dir)
    assert run.meta["status"] == "completed"
    assert run.trials["trial_id"].is_unique and len(run.trials) == 150
    assert [i["kind"] for i in run.meta["interruptions"]].count("crash") == kills
    expected = load_run(reference.run_id, tmp_path / "reference")
    cols = [c for c in OUTCOME if c != "t_start_s"]  # a resumed session has its own clock
    a = run.trials.sort_values("trial_id")[cols].reset_index(drop=True)
    b = expected.trials.sort_values("trial_id")[cols].reset_index(drop=True)
    pd.testing.assert_frame_equal(a, b, check_exact=False, rtol=1e-9, atol=1e-12)
    for table, keys in (("samples", ["trial_id", "source"]), ("midi", ["trial_id"])):
        ours = getattr(run, table).groupby(keys).size().sort_index()
        theirs = getattr(expected, table).groupby(keys).size().sort_index()
        pd.testing.assert_series_equal(ours, theirs)
    assert not list((run.path / "parts").iterdir())


def _start_blocks(spec: Path, data_dir: Path, resume: str | None) -> subprocess.Popen[bytes]:
    """`pianobot sweep` in a subprocess with the default block size (128 trials)."""
    args = [sys.executable, "-c", SWEEP_ONLY, "sweep", str(spec), "--data", str(data_dir),
            "--json", "--no-progress", "--seed", "3"]
    if resume is not None:
        args += ["--resume", resume]
    return subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
