"""Whole sweeps on a rig file pointing at the emulated UR (real ur_rtde) and its JACK piano.

Nothing here is faked on pianobot's side: `pianobot sweep` (or `run_sweep`) opens the rig from
the YAML file, ur_rtde talks RTDE, dashboard and script to the emulated controller, the
emulated regulator settles on the UR's analog output, and the emulated piano's notes come back
through a JACK MIDI port. Skipped without jackd (CI installs it) or without ur_rtde.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from cli_runner import invoke_cli
from emulated_lab import HOVER_POSE, piano, write_lab, write_spec
from hardware_emulator import CB3, ESERIES, EmulatedUR
from hardware_emulator.fixtures import EmulatorFactory

from pianobot.run import RunOutcome, RunStarted, TrialStarted, run_sweep
from pianobot.store import load_run

MOVEL = 3
pytestmark = pytest.mark.slow  # real-time motion on the emulated arm: ~5-15 s each


@pytest.fixture()
def lab(ur_emulator: EmulatorFactory, jack_server: str, tmp_path: Path) -> Any:
    """Start an emulated lab; return (emulator, spec path, rig path)."""

    def start(*, spec: dict[str, Any] | None = None, lost_note_ons: tuple[int, ...] = (),
              **config: Any) -> tuple[EmulatedUR, Path]:
        keys = replace(piano(), lost_note_ons=lost_note_ons)
        ur = ur_emulator(piano=keys, start_pose=HOVER_POSE, **config)
        rig = write_lab(tmp_path, ur.host, keys)
        return ur, write_spec(tmp_path, rig, **(spec or {}))

    return start


def sweep(spec: Path, data: Path, records: list[Any] | None = None) -> RunOutcome:
    return run_sweep(spec, data_dir=data, progress=False,
                     subscribers=[records.append] if records is not None else [])


@pytest.mark.parametrize(("generation", "rate_hz", "approach"), [
    (CB3, 125.0, "as-specified"), (ESERIES, 500.0, "fast"),
])
def test_a_full_small_sweep(
    lab: Any, data_dir: Path, generation: str, rate_hz: float, approach: str,
) -> None:
    distance_m = 0.005 if approach == "as-specified" else 0.03
    ur, spec = lab(generation=generation, spec={"approach": approach, "distance_m": distance_m})
    outcome = sweep(spec, data_dir)
    assert outcome.status == "completed" and outcome.trials == 4, outcome.reason
    run = load_run(outcome.run_id, data_dir)
    trials = run.trials.sort_values("index")
    assert list(trials["status"]) == ["ok"] * 4 and set(trials["note"]) == {59}
    # The piano's loudness follows the commanded speed at each vacuum level.
    for _, level in trials.groupby("vacuum_kpa"):
        slow, fast = level.sort_values("down_velocity_mps")["on_velocity"]
        assert fast > slow
    arm = run.samples[run.samples["source"] == "arm"]
    travel_m = distance_m + 0.02
    assert arm.groupby("trial_id")["x0_m"].max().to_numpy() == pytest.approx(travel_m, abs=1e-6)
    if approach == "fast":  # a fast approach, the spec's moves, and a fast retract if planned
        assert (trials["approach_m"] > 0.01).all()
        per_press = 2 + (trials["approach_m"] > 0) + (trials["retract_m"] > 0)
        assert ur.get("commands").count(MOVEL) == 1 + per_press.sum()
    described = run.meta["rig"]["description"]["devices"]
    assert described["arm"]["rtde_rate_hz"] == rate_hz
    assert described["arm"]["controller"]["generation"] == ("CB3" if generation == CB3
                                                            else "e-Series")
    assert described["vacuum"]["kpa_span"] == [0.0, -80.0]
    assert ur.output_frequencies() == [rate_hz] * 2  # receive + control, once each
    assert ur.regulator_kpa() == pytest.approx(0.0, abs=2.0)  # vented at the end


def test_a_link_dropped_mid_press_is_recovered_by_retrying_the_trial(
    lab: Any, data_dir: Path,
) -> None:
    ur, spec = lab()
    # Moves: hover (1), trial 0 down/up (2, 3), trial 1 down (4): drop the link half-way.
    ur.fail_on_move(4, "drop_links", fraction=0.5, outage_s=0.3)
    outcome = sweep(spec, data_dir)
    assert outcome.status == "completed" and outcome.trials == 4, outcome.reason
    run = load_run(outcome.run_id, data_dir)
    # (A note-on JACK lost under load would be retried too, and journalled with its own error.)
    retried = [e for e in run.journal if e.get("event") == "retried"
               and "note-on lost" not in e["error"]]
    assert len(retried) == 1 and retried[0]["index"] == 1
    assert "connection lost" in retried[0]["error"]
    trials = run.trials.set_index("index")
    assert trials.loc[1, "attempt"] == 2 and (trials["status"] == "ok").all()


def test_a_note_on_lost_on_the_way_is_pressed_again_once_the_plan_has_run(
    lab: Any, data_dir: Path,
) -> None:
    ur, spec = lab(lost_note_ons=(1,))  # trial 1's note-on never reaches pianobot
    records: list[Any] = []
    outcome = sweep(spec, data_dir, records)
    assert outcome.status == "completed" and outcome.trials == 4 and outcome.failed == 0
    run = load_run(outcome.run_id, data_dir)
    retried = [e for e in run.journal if e.get("event") == "retried"]
    assert [(e["index"], e["attempt"]) for e in retried] == [(1, 1)]
    assert "note-on lost" in retried[0]["error"]
    # Pressed again after trial 3, as attempt 2; the lost attempt left no samples or MIDI.
    started = [(r.index, r.attempt) for r in records if isinstance(r, TrialStarted)]
    assert started == [(0, 1), (1, 1), (2, 1), (3, 1), (1, 2)]
    trials = run.trials.set_index("index")
    assert (trials["status"] == "ok").all() and trials.loc[1, "attempt"] == 2
    assert len(ur.piano_events()) == 10  # five keystrokes played, one note-on lost
    redone = trials.loc[1, "trial_id"]
    assert (run.midi["trial_id"] == redone).sum() == 2  # its note-on and note-off, once
    arm = run.samples[(run.samples["source"] == "arm") & (run.samples["trial_id"] == redone)]
    assert arm["t_s"].is_unique


def test_a_protective_stop_is_never_retried_and_named_in_run_json(
    lab: Any, data_dir: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    ur, spec = lab()
    ur.fail_on_move(4, "protective_stop", fraction=0.4)
    code, out, err = invoke_cli(["sweep", str(spec), "--data", str(data_dir), "--no-progress"],
                                capsys, monkeypatch)
    assert code == 3, err  # stopped by a safety stop
    (run_dir,) = (data_dir / "runs").iterdir()
    meta = json.loads((run_dir / "run.json").read_text())
    assert meta["status"] == "stopped"
    assert "protective stopped" in meta["reason"] and "teach pendant" in meta["reason"]
    assert [i["kind"] for i in meta["interruptions"]] == ["safety_stop"]
    journal = [json.loads(line) for line in (run_dir / "journal.jsonl").read_text().splitlines()]
    assert not [e for e in journal if e.get("event") == "retried"]
    assert ur.get("commands").count(MOVEL) == 4  # nothing moved after the stop
    assert "resume:" in out


def test_a_slow_speed_slider_is_warned_before_any_motion(
    lab: Any, data_dir: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    ur, spec = lab(speed_slider=0.3, spec={"vacuum_kpa": (0.0,), "down_velocity_mps": (0.05,)})
    moved_at_start: list[list[int]] = []

    def at_run_start(record: Any) -> None:
        if isinstance(record, RunStarted):
            moved_at_start.append(ur.get("commands"))
            assert record.warnings, "no warning before the run"

    records: list[Any] = []
    outcome = run_sweep(spec, data_dir=data_dir, progress=False,
                        subscribers=[at_run_start, records.append])
    assert outcome.status == "completed"
    assert moved_at_start and MOVEL not in moved_at_start[0]  # warned before the first move
    kinds = [type(r).__name__ for r in records]
    assert kinds.index("RunStarted") < kinds.index("TrialStarted")
    assert any("speed slider is at 30 %" in w for w in outcome.warnings)
    meta = load_run(outcome.run_id, data_dir).meta
    assert any("30 %" in w for w in meta["rig"]["warnings"])
    # The command line prints it on stderr before the run starts.
    code, _, err = invoke_cli(["sweep", str(spec), "--data", str(data_dir), "--no-progress"],
                              capsys, monkeypatch)
    assert code == 0 and "warning: the teach pendant's speed slider is at 30 %" in err
    assert isinstance(records[1], TrialStarted)


def test_a_paused_program_stops_the_run_and_a_paused_robot_is_refused(
    lab: Any, data_dir: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    ur, spec = lab()
    ur.fail_on_move(2, "pause", fraction=0.5)  # trial 0's down stroke
    outcome = sweep(spec, data_dir)
    assert outcome.status == "stopped" and "paused" in str(outcome.reason)
    assert ur.paused and ur.counts()["programs"] == 1  # never uploaded over the pause
    # The program is still paused: the next sweep is refused before anything is written.
    runs_before = sorted((data_dir / "runs").iterdir())
    code, _, err = invoke_cli(["sweep", str(spec), "--data", str(data_dir)], capsys, monkeypatch)
    assert code == 2 and "paused" in err and len(err.strip().splitlines()) == 1
    assert sorted((data_dir / "runs").iterdir()) == runs_before
