"""Fault drill on experiments/rigs/sim-faulty.yaml: retries recorded, protective stop, resume."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_runner import invoke_cli as cli

from pianobot.spec import load_rig
from pianobot.store import load_run

REPO = Path(__file__).resolve().parents[2]
QUICKSTART = REPO / "experiments" / "quickstart.yaml"
FAULTY = REPO / "experiments" / "rigs" / "sim-faulty.yaml"




def test_faulty_rig_retries_stops_and_resumes_to_completion(
    data_dir: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    rig = load_rig(FAULTY)
    stop_at = rig.faults.protective_stop_at_trial
    every = rig.faults.drop_connection_every_n_presses
    assert stop_at is not None and every is not None  # the drill needs both faults

    base = ["sweep", str(QUICKSTART), "--rig", str(FAULTY), "--data", str(data_dir), "--json"]
    code, out, err = cli(base, capsys, monkeypatch)
    first = json.loads(out)
    assert code == 3, err  # stopped by a safety stop
    assert first["status"] == "stopped" and f"trial {stop_at}" in first["reason"]
    run_id = first["run_id"]
    run = load_run(run_id, data_dir)
    assert run.meta["status"] == "stopped" and run.meta["reason"] == first["reason"]
    assert [i["kind"] for i in run.meta["interruptions"]] == ["safety_stop"]
    assert first["trials"] == stop_at  # every trial before the stop, none after
    assert set(run.trials["index"]) == set(range(stop_at))
    stop_events = [e for e in run.journal if e["event"] == "failed" and e.get("kind") == "safety_stop"]
    assert [e["index"] for e in stop_events] == [stop_at]

    # The operator clears the stop and resumes; the spec is found from the run itself.
    code, out, err = cli(["sweep", "--resume", run_id, "--data", str(data_dir), "--json"], capsys, monkeypatch)
    second = json.loads(out)
    assert code == 0, err
    assert second["status"] == "completed" and second["trials"] == second["planned"] == 16

    run = load_run(run_id, data_dir)
    trials = run.trials
    assert trials["trial_id"].is_unique and sorted(trials["trial_id"]) == sorted(run.plan["trial_id"])
    assert set(trials["status"]) <= {"ok", "silent"}
    # Every retry is in the journal and in the attempt column.
    retried = [e for e in run.journal if e["event"] == "retried"]
    assert len(retried) >= 1  # the 7th press of the first session drops
    assert all("connection lost" in e["error"] for e in retried)
    by_trial = {}
    for event in retried:
        by_trial[event["trial_id"]] = by_trial.get(event["trial_id"], 0) + 1
    attempts = trials.set_index("trial_id")["attempt"]
    for trial_id, n in by_trial.items():
        assert attempts[trial_id] == n + 1
    assert (attempts.drop(index=list(by_trial)) == 1).all()
    assert [e["event"] for e in run.journal].count("resumed") == 1
    assert "stop_cleared" in [e["event"] for e in run.journal]
    assert run.meta["status"] == "completed" and run.meta["sessions"] == 2
    # Injected mocap drops appear as NaN frames; arm and truth traces are complete.
    samples = run.samples
    mocap = samples[samples["source"] == "mocap"]
    assert np.isnan(mocap["x2_m"]).any() and not np.isnan(mocap["t_s"]).any()
    assert not np.isnan(samples[samples["source"] == "arm"]["x0_m"]).any()
