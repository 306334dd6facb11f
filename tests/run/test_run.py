"""The runner on the sim rig: records, tables, journal, retries, stops, interrupts, resume.

A small stand-in World keeps these tests fast and independent of the physics; the crash test
(tests/run/test_crash_resume.py) runs the real world through the command line.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

import pianobot
from pianobot.errors import InputError
from pianobot.physics.trajectory import Press, press_duration_s
from pianobot.run import (
    Record,
    RunEnded,
    RunStarted,
    StopControl,
    TrialDone,
    TrialRetried,
    TrialStarted,
    TrialStopped,
    run_sweep,
)
from pianobot.store import load_run, read_journal
from pianobot.store.schema import TRIALS_SCHEMA

OUTCOME = ["trial_id", "index", "status", "on_velocity", "off_velocity", "t_on_s", "t_off_s",
           "midi_hold_s", "n_note_on", "key_speed_at_trigger_mps", "max_key_travel_m"]


@dataclass(frozen=True)
class Event:
    t_s: float
    type: str
    note: int
    velocity: int


class FakeWorld:
    """Pure in (press, vacuum, note, key): loud above 0.02 m/s, silent below."""

    def vacuum_settle_s(self, from_kpa: float, to_kpa: float) -> float:
        return 0.02 * abs(to_kpa - from_kpa)

    def keystroke(self, press: Press, vacuum_kpa: float, *, note: int, t0_s: float, key: str) -> Any:
        jitter = hashlib.sha256(key.encode()).digest()[0] / 255.0
        duration = press_duration_s(press)
        t = np.linspace(0.0, duration, 40)
        x0 = (press.distance_m + press.depth_m) * np.sin(np.pi * t / duration)
        x2 = np.clip(x0 - press.distance_m, 0.0, 0.01)
        midi: tuple[Event, ...] = ()
        if press.down_velocity_mps > 0.02:
            velocity = int(min(127, 20 + 1000 * press.down_velocity_mps + 0.3 * abs(vacuum_kpa) + 9 * jitter))
            midi = (Event(t0_s + 0.4 * duration, "note_on", note, velocity),
                    Event(t0_s + 0.7 * duration, "note_off", note, 40))
        mt = t[::3]
        return type("Stroke", (), dict(
            t0_s=t0_s, duration_s=duration, truth_t_s=t + t0_s, truth_x0_m=x0, truth_x1_m=0.9 * x0,
            truth_x2_m=x2, arm_t_s=t + t0_s, arm_x0_m=x0, mocap_t_s=mt + t0_s, mocap_x0_m=x0[::3],
            mocap_x1_m=0.9 * x0[::3], mocap_x2_m=x2[::3], midi=midi,
            key_speed_at_trigger_mps=0.5 * press.down_velocity_mps + 0.01 * jitter,
            max_key_travel_m=float(x2.max()),
        ))


SPEC = """\
name: runner-test
rig: {rig}
finger: soft
note: 60
sweep:
  mode: grid
  params:
    vacuum_kpa: [0, -40]
    down_velocity_mps: [0.015, 0.03, 0.045, 0.06]
    depth_m: [0.02, 0.03]
  fixed: {{acceleration_mps2: 1.0, distance_m: 0.05, hold_s: 0.0}}
  order: blocked-shuffle
  seed: 3
record: {record}
"""


def _spec(tmp_path: Path, *, rig: str = "sim", record: str = "[midi, arm, mocap]", faults: str = "",
          retry: str = "") -> Path:
    if faults or retry:
        (tmp_path / "rig.yaml").write_text(f"kind: sim\nseed: 5\n{faults}\n{retry}\n")
        rig = "rig.yaml"
    path = tmp_path / "spec.yaml"
    path.write_text(SPEC.format(rig=rig, record=record))
    return path


class Collector:
    def __init__(self, action: Any = None) -> None:
        self.records: list[Record] = []
        self.action = action

    def __call__(self, record: Record) -> None:
        self.records.append(record)
        if self.action is not None:
            self.action(self, record)

    def of(self, kind: type) -> list[Any]:
        return [r for r in self.records if isinstance(r, kind)]


def _run(spec: Path | None, data_dir: Path, **kw: Any) -> Any:
    kw.setdefault("progress", False)
    return run_sweep(spec, data_dir=data_dir, world=FakeWorld(), **kw)


def test_a_sweep_writes_every_trial_with_midi_outcome_samples_and_provenance(tmp_path: Path, data_dir: Path) -> None:
    spec = _spec(tmp_path)
    collector = Collector()
    outcome = _run(spec, data_dir, subscribers=[collector], batch_trials=5)
    assert (outcome.status, outcome.trials, outcome.planned, outcome.failed) == ("completed", 16, 16, 0)
    assert outcome.silent == 4  # the 0.015 m/s presses do not sound
    run = load_run(outcome.run_id, data_dir)
    trials, plan = run.trials, run.plan
    assert list(trials.columns) == TRIALS_SCHEMA.names
    assert sorted(trials["trial_id"]) == sorted(plan["trial_id"]) and trials["trial_id"].is_unique
    silent = trials[trials["status"] == "silent"]
    assert set(silent["down_velocity_mps"]) == {0.015}
    assert silent["on_velocity"].isna().all() and (silent["n_note_on"] == 0).all()
    ok = trials[trials["status"] == "ok"]
    assert (ok["attempt"] == 1).all() and (ok["n_note_on"] == 1).all()
    assert ((ok["t_on_s"] > 0) & (ok["t_off_s"] > ok["t_on_s"])).all()
    assert np.allclose(ok["midi_hold_s"], ok["t_off_s"] - ok["t_on_s"])
    assert ok["t_start_s"].is_monotonic_increasing
    # Louder with more vacuum: the readout keeps the parameters next to the outcome.
    assert ok[ok.vacuum_kpa == -40]["on_velocity"].mean() > ok[ok.vacuum_kpa == 0]["on_velocity"].mean()
    samples = run.samples
    assert set(samples["source"]) == {"arm", "mocap", "sim-truth"}
    assert set(samples["trial_id"]) == set(trials["trial_id"])
    assert samples["t_s"].min() >= 0.0
    midi = run.midi
    assert len(midi) == 2 * len(ok)
    first_on = midi[midi.type == "note_on"].set_index("trial_id")["t_s"]
    joined = ok.set_index("trial_id")
    assert np.allclose(first_on.loc[joined.index], joined["t_start_s"] + joined["t_on_s"])
    meta = run.meta
    assert meta["status"] == "completed" and meta["seed"] == 0
    assert meta["spec"]["text"] == spec.read_text()
    assert meta["spec_sha256"] == hashlib.sha256(spec.read_bytes()).hexdigest()
    assert meta["pianobot_version"] == pianobot.__version__
    assert meta["rig"]["description"]["kind"] == "sim"
    assert meta["lab_time_s"] == pytest.approx(outcome.lab_time_s) and outcome.lab_time_s > 16 * 0.5
    # Records: started, then one start/done pair per trial, then the end.
    assert isinstance(collector.records[0], RunStarted) and isinstance(collector.records[-1], RunEnded)
    assert len(collector.of(TrialStarted)) == len(collector.of(TrialDone)) == 16
    events = [e["event"] for e in run.journal]
    assert events[0] == "run_started" and events[-1] == "run_ended"
    assert events.count("started") == events.count("done") == 16


def test_journal_done_lines_follow_their_part(tmp_path: Path, data_dir: Path) -> None:
    seen: list[tuple[int, int]] = []

    def check(c: Collector, record: Record) -> None:
        if isinstance(record, TrialStarted):
            run = load_run(c.run_id, data_dir)  # type: ignore[attr-defined]
            done = [e for e in run.journal if e["event"] == "done"]
            seen.append((len(done), len(run.trials)))

    collector = Collector(check)

    def remember(c: Collector, record: Record) -> None:
        if isinstance(record, RunStarted):
            c.run_id = record.run_id  # type: ignore[attr-defined]
        check(c, record)

    collector.action = remember
    _run(_spec(tmp_path), data_dir, subscribers=[collector], batch_trials=3)
    assert all(done <= rows for done, rows in seen)
    assert any(rows > 0 for _, rows in seen) and any(done < 16 for done, _ in seen)


def test_record_midi_only_keeps_no_samples(tmp_path: Path, data_dir: Path) -> None:
    outcome = _run(_spec(tmp_path, record="[midi]"), data_dir)
    run = load_run(outcome.run_id, data_dir)
    assert run.samples.empty and len(run.midi) > 0 and len(run.trials) == 16


def test_dropped_connections_are_retried_and_recorded(tmp_path: Path, data_dir: Path) -> None:
    spec = _spec(tmp_path, faults="faults: {drop_connection_every_n_presses: 5}",
                 retry="retry: {max_attempts: 3, backoff_s: 2.0, backoff_factor: 3.0}")
    collector = Collector()
    outcome = _run(spec, data_dir, subscribers=[collector])
    assert outcome.status == "completed" and outcome.trials == 16
    run = load_run(outcome.run_id, data_dir)
    retried = [e for e in run.journal if e["event"] == "retried"]
    assert len(retried) == outcome.retries == len(collector.of(TrialRetried)) >= 3
    assert all("connection lost" in e["error"] for e in retried)
    assert {e["backoff_s"] for e in retried} == {2.0}
    retried_ids = {e["trial_id"] for e in retried}
    trials = run.trials.set_index("trial_id")
    assert (trials.loc[sorted(retried_ids), "attempt"] == 2).all()
    assert (trials.drop(index=sorted(retried_ids))["attempt"] == 1).all()


def test_exhausted_retries_fail_the_trial_and_the_run(tmp_path: Path, data_dir: Path) -> None:
    spec = _spec(tmp_path, faults="faults: {drop_connection_every_n_presses: 1}",
                 retry="retry: {max_attempts: 2, backoff_s: 0.1}")
    outcome = _run(spec, data_dir)
    assert outcome.status == "failed" and "after 2 attempts" in (outcome.reason or "")
    run = load_run(outcome.run_id, data_dir)
    (failed,) = run.trials.itertuples()
    assert failed.status == "failed" and failed.attempt == 2 and "connection lost" in failed.error
    assert [e["event"] for e in run.journal].count("failed") == 1


def test_protective_stop_stops_and_resume_continues(tmp_path: Path, data_dir: Path) -> None:
    spec = _spec(tmp_path, faults="faults: {protective_stop_at_trial: 6}")
    collector = Collector()
    first = _run(spec, data_dir, subscribers=[collector])
    assert first.status == "stopped" and "trial 6" in (first.reason or "")
    assert first.trials == 6
    (stopped,) = collector.of(TrialStopped)
    assert stopped.index == 6
    run = load_run(first.run_id, data_dir)
    assert run.meta["reason"] == first.reason
    assert [i["kind"] for i in run.meta["interruptions"]] == ["safety_stop"]
    second = _run(None, data_dir, resume=first.run_id[:20])
    assert (second.status, second.trials, second.resumed) == ("completed", 16, True)
    run = load_run(first.run_id, data_dir)
    assert run.trials["trial_id"].is_unique and len(run.trials) == 16
    assert "stop_cleared" in [e["event"] for e in run.journal]
    assert "software_sessions" not in run.meta  # the same pianobot resumed: nothing to record


def test_a_resume_by_another_pianobot_is_recorded_and_shown(
    tmp_path: Path, data_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A run resumed after an upgrade holds data of two versions: run.json and the summary
    name both (the run used to keep only its first session's version and commit)."""
    from pianobot.run import resume
    from pianobot.store import software_summary

    first = _run(_spec(tmp_path, faults="faults: {protective_stop_at_trial: 6}"), data_dir)
    assert first.status == "stopped"
    recorded = load_run(first.run_id, data_dir).meta
    assert software_summary(recorded) == (
        f"pianobot {pianobot.__version__}"
        + (f" (git {recorded['git_commit'][:10]})" if recorded.get("git_commit") else ""))
    monkeypatch.setattr(pianobot, "__version__", "9.9.9")
    monkeypatch.setattr(resume, "git_commit", lambda: "f" * 40)
    assert _run(None, data_dir, resume=first.run_id).status == "completed"
    meta = load_run(first.run_id, data_dir).meta
    assert [(s["sessions_from"], s["pianobot_version"]) for s in meta["software_sessions"]] == [
        (1, recorded["pianobot_version"]), (2, "9.9.9")]
    assert meta["software_sessions"][1]["git_commit"] == "f" * 40
    shown = software_summary(meta)
    assert shown.startswith("MIXED: 2 versions over 2 sessions") and "pianobot 9.9.9 (git ffffffffff) from session 2" in shown


def test_first_interrupt_finishes_the_trial_then_resume_matches_an_uninterrupted_run(
    tmp_path: Path, data_dir: Path
) -> None:
    spec = _spec(tmp_path)
    reference = load_run(_run(spec, data_dir).run_id, data_dir).trials

    control = StopControl(notify=lambda message: None)

    def stop_after_five(c: Collector, record: Record) -> None:
        if isinstance(record, TrialStarted) and record.index == 5:
            control.on_signal(2)  # SIGINT while trial 5 is running

    outcome = _run(spec, data_dir, control=control, subscribers=[Collector(stop_after_five)])
    assert outcome.status == "interrupted" and outcome.trials == 6  # trial 5 was finished
    meta = load_run(outcome.run_id, data_dir).meta
    assert meta["interruptions"][0]["kind"] == "signal"
    resumed = _run(spec, data_dir, resume=outcome.run_id)
    assert resumed.status == "completed"
    final = load_run(outcome.run_id, data_dir).trials
    _assert_same_outcomes(final, reference)
    assert final["t_start_s"].is_monotonic_increasing  # the run clock continues on resume


def test_second_interrupt_stops_at_once_and_the_trial_is_redone(tmp_path: Path, data_dir: Path) -> None:
    spec = _spec(tmp_path)
    reference = load_run(_run(spec, data_dir).run_id, data_dir).trials
    control = StopControl(notify=lambda message: None)

    def twice(c: Collector, record: Record) -> None:
        if isinstance(record, TrialStarted) and record.index == 9:
            control.on_signal(15)
            control.on_signal(15)  # raises KeyboardInterrupt inside the trial

    outcome = _run(spec, data_dir, control=control, subscribers=[Collector(twice)])
    assert outcome.status == "interrupted" and outcome.trials == 9
    assert "twice" in (outcome.reason or "")
    journal = read_journal(outcome.path / "journal.jsonl")
    started_9 = [e for e in journal if e["event"] == "started" and e["index"] == 9]
    assert len(started_9) == 1 and not [e for e in journal if e["event"] == "done" and e["index"] == 9]
    _run(spec, data_dir, resume=outcome.run_id)
    _assert_same_outcomes(load_run(outcome.run_id, data_dir).trials, reference)


def test_resume_refuses_a_changed_spec_and_a_completed_run_has_nothing_to_do(
    tmp_path: Path, data_dir: Path
) -> None:
    spec = _spec(tmp_path)
    outcome = _run(spec, data_dir)
    again = _run(spec, data_dir, resume=outcome.run_id)
    assert again.status == "completed" and again.executed == 0
    # A comment added is no change of the experiment: the resume goes on (it used to be refused).
    original = spec.read_text()
    spec.write_text("# checked by M. before the second session\n" + original)
    assert _run(spec, data_dir, resume=outcome.run_id).status == "completed"
    spec.write_text(original.replace("seed: 3", "seed: 4"))
    with pytest.raises(InputError, match="its settings changed"):
        _run(spec, data_dir, resume=outcome.run_id)
    with pytest.raises(InputError, match="pianobot runs"):
        _run(spec, data_dir, resume="nope")


@pytest.mark.parametrize(
    "text",
    [
        "name: bad\nfinger: soft\nsweep: {mode: grid, params: {down_velocity_mps: [0.03]}, fixed: {depth_m: 0.02}}\nbogus: 1\n",
        "name: bad\nfinger: soft\nsweep: {mode: grid, params: {down_velocity_mps: [0.5], depth_m: [0.02]}}\n",
        "name: bad\nfinger: soft\nsweep: {mode: grid, params: {down_velocity_mps: [], depth_m: [0.02]}}\n",
        "name: bad\nfinger: [soft\n",
    ],
)
def test_bad_specs_raise_before_any_run_folder_exists(tmp_path: Path, data_dir: Path, text: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(InputError):
        _run(path, data_dir)
    assert not (data_dir / "runs").exists() or not any((data_dir / "runs").iterdir())


def _assert_same_outcomes(final: pd.DataFrame, reference: pd.DataFrame) -> None:
    """Trial by trial, the outcome columns agree (times relative to motion start)."""
    a = final.sort_values("trial_id")[OUTCOME].reset_index(drop=True)
    b = reference.sort_values("trial_id")[OUTCOME].reset_index(drop=True)
    pd.testing.assert_frame_equal(a, b, check_exact=False, rtol=1e-9, atol=1e-9)


def test_outcome_json_is_serialisable(tmp_path: Path, data_dir: Path) -> None:
    outcome = _run(_spec(tmp_path), data_dir)
    payload = json.loads(json.dumps(outcome.to_dict()))
    assert {"run_id", "status", "trials", "silent"} <= set(payload)


def test_progress_bar_shows_done_total_lab_eta_retries_and_parameters(tmp_path: Path, data_dir: Path) -> None:
    import io

    from rich.console import Console

    from pianobot.progress import RichProgress
    from pianobot.run.progress import ProgressBar

    stream = io.StringIO()
    display = RichProgress(Console(file=stream, width=200, force_terminal=False))
    spec = _spec(tmp_path, faults="faults: {drop_connection_every_n_presses: 6}")
    with ProgressBar(display) as bar:
        frames: list[str] = []

        def snapshot(c: Collector, record: Record) -> None:
            if isinstance(record, TrialDone) and record.data.row["index"] == 8:
                (task,) = display._display.tasks
                frames.append(f"{task.fields['note']} {task.completed}")

        _run(spec, data_dir, subscribers=[bar, Collector(snapshot)])
    (frame,) = frames
    assert "9" in frame.split()[-1]  # nine trials done of 16
    assert "1 retry" in frame and "kPa" in frame and "mm/s" in frame
    assert "lab ? left" not in frame and "left" in frame
    text = stream.getvalue()
    assert "16/16" in text and "ETA" in text
