"""`approach: fast` from the spec to the data: plan, lab time, dry run, station, sweep."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest
from cli_runner import invoke_cli

from pianobot.physics.approach import ApproachSettings
from pianobot.physics.trajectory import Press, press_duration_s, press_timing
from pianobot.plan import Trial, expand, lab_time, plan_frame
from pianobot.plan.approach import approach_settings, as_specified, with_fast_approach
from pianobot.plan.trial import FAST_PLAN_COLUMNS, PLAN_COLUMNS
from pianobot.rig import open_rig
from pianobot.rig.errors import SafetyViolation
from pianobot.run import run_sweep
from pianobot.spec import ExperimentSpec, RigSpec
from pianobot.store import load_run

REPO = Path(__file__).resolve().parents[2]
GRID = REPO / "experiments" / "soft_finger_grid.yaml"
SWEEP: dict[str, Any] = {
    "mode": "grid",
    "params": {"vacuum_kpa": [-40, -80], "down_velocity_mps": [0.01, 0.03, 0.06],
               "depth_m": [0.025, 0.035]},
    "fixed": {"distance_m": 0.05, "acceleration_mps2": 0.5},
}


def spec(**top: Any) -> ExperimentSpec:
    return ExperimentSpec.model_validate({"name": "fast", "finger": "soft", "sweep": SWEEP, **top})


def test_default_keeps_old_specs_and_their_trial_ids() -> None:
    old = spec()
    assert old.approach == "as-specified"
    explicit = spec(approach="as-specified")
    assert [t.trial_id for t in expand(old)] == [t.trial_id for t in expand(explicit)]
    fast = spec(approach="fast")
    # A fast sweep commands other motions, so its trials are other trials.
    assert not set(t.trial_id for t in expand(fast)) & set(t.trial_id for t in expand(old))
    with pytest.raises(ValueError):
        spec(approach="quick")


def test_rig_and_physics_defaults_agree() -> None:
    assert approach_settings(RigSpec()) == ApproachSettings()


def test_fast_plan_keeps_parameters_and_saves_lab_time() -> None:
    rig = RigSpec()
    plain = expand(spec())
    fast = with_fast_approach(plain, rig)
    assert [t.parameters() for t in fast] == [t.parameters() for t in plain]
    assert as_specified(fast) == plain
    assert list(plan_frame(plain).columns) == list(PLAN_COLUMNS)
    assert list(plan_frame(fast).columns) == list(FAST_PLAN_COLUMNS)
    slow_t, fast_t = lab_time(plain, rig), lab_time(fast, rig)
    assert fast_t.presses_s < slow_t.presses_s and fast_t.total_s < slow_t.total_s
    # Presses are their exact durations; the pause after a press starts at lift-off.
    assert fast_t.presses_s == pytest.approx(sum(press_duration_s(t.press()) for t in fast))
    assert fast_t.pauses_s < slow_t.pauses_s == pytest.approx(0.5 * len(plain))
    # The slowest presses gain most: at 0.01 m/s the 5 cm run-up alone took 5 s.
    slowest = [(p, f) for p, f in zip(plain, fast, strict=True) if p.down_velocity_mps == 0.01]
    for p, f in slowest:
        assert press_duration_s(f.press()) < 0.6 * press_duration_s(p.press())


def test_study_grid_lab_time_with_the_fast_approach() -> None:
    """The figure `make bench` reports: the study's grid, fast approach vs the study's script."""
    from pianobot.run import prepare_sweep

    prepared = prepare_sweep(GRID)
    study_s = sum(press_duration_s(t.press()) + 1.0 for t in prepared.trials)  # 0.5 s before + after
    fast_s = lab_time(with_fast_approach(prepared.trials, prepared.rig), prepared.rig).total_s
    plain_s = lab_time(prepared.trials, prepared.rig).total_s
    assert fast_s < 0.75 * plain_s
    assert 0.5 < fast_s / study_s < 0.7  # see docs/architecture.md for why not 0.5


def test_dry_run_shows_both_lab_times(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "fast.yaml"
    path.write_text(json.dumps({"name": "fast", "finger": "soft", "sweep": SWEEP}))
    code, out, _ = invoke_cli(["sweep", str(path), "--dry-run", "--json"], capsys, monkeypatch)
    assert code == 0
    data = json.loads(out)
    both = data["lab_time_by_approach"]
    assert data["approach"] == "as-specified"
    assert both["fast"]["total_s"] < both["as-specified"]["total_s"] == data["lab_time"]["total_s"]
    code, out, _ = invoke_cli(["sweep", str(path), "--dry-run"], capsys, monkeypatch)
    assert "fast approach" in out and "approach: fast" in out
    path.write_text(json.dumps({"name": "fast", "finger": "soft", "sweep": SWEEP, "approach": "fast"}))
    code, out, _ = invoke_cli(["sweep", str(path), "--dry-run", "--json"], capsys, monkeypatch)
    data = json.loads(out)
    assert data["lab_time"]["total_s"] == data["lab_time_by_approach"]["fast"]["total_s"]
    path.write_text(json.dumps({"name": "fast", "finger": "soft", "sweep": SWEEP, "approach": "x"}))
    code, _, err = invoke_cli(["sweep", str(path), "--dry-run"], capsys, monkeypatch)
    assert code == 2 and "approach" in err and len(err.strip().splitlines()) == 1


def _trial(press: Press, **extra: float) -> Trial:
    return Trial("t0", 0, 0, 57, -40.0, press.down_velocity_mps, press.up_velocity_mps,
                 press.acceleration_mps2, press.depth_m, press.distance_m, press.hold_s, 0.0,
                 **extra)


def test_station_refuses_a_fast_move_into_the_key_and_overlaps_the_pause() -> None:
    with open_rig(RigSpec()) as rig:
        bad = _trial(Press(0.05, 0.03, 0.02, 0.02, 0.5), approach_m=0.06)
        rig.set_vacuum(-40.0)
        rig.move_to_key(57, 0.05)
        with pytest.raises(SafetyViolation, match="above the key"):
            rig.keystroke(bad)
        plain = expand(spec())[0]
        fast = with_fast_approach([plain], RigSpec())[0]
        assert fast.retract_m > 0
        t0 = rig.clock.now()
        result = rig.keystroke(fast)
        took = rig.clock.now() - t0
        arm_s = result.press.t_end_s - result.press.t_start_s
        assert arm_s == pytest.approx(press_duration_s(fast.press()), abs=0.01)
        # The pause after the press starts at lift-off: the fast retract is part of it.
        retract_s = press_timing(fast.press()).retract.duration_s
        assert 0.0 < retract_s < 0.5
        assert took == pytest.approx(arm_s + 0.5 - retract_s, abs=1e-6)


def test_fast_sweep_records_the_commanded_moves(tmp_path: Path) -> None:
    path = tmp_path / "fast.yaml"
    path.write_text(json.dumps({"name": "fast", "finger": "soft", "sweep": SWEEP, "approach": "fast",
                                "record": ["midi", "arm"]}))
    outcome = run_sweep(path, data_dir=tmp_path / "data", progress=False)
    assert outcome.status == "completed" and outcome.trials == 12
    run = load_run(outcome.run_id, tmp_path / "data")
    assert list(run.plan.columns) == list(FAST_PLAN_COLUMNS)
    trials = run.trials.set_index("trial_id")
    plan = run.plan.set_index("trial_id")
    assert (trials["approach_m"] == plan.loc[trials.index, "approach_m"]).all()
    assert (trials["approach_m"] > 0).sum() >= 4 and (trials["retract_m"] > 0).all()
    # The arm trace follows the four moves: it reaches the bottom and comes back.
    arm = run.samples[run.samples["source"] == "arm"]
    for trial_id, rows in arm.groupby("trial_id"):
        row = trials.loc[trial_id]
        assert rows["x0_m"].max() == pytest.approx(row["distance_m"] + row["depth_m"], abs=1e-4)
    assert math.isfinite(outcome.lab_time_s) and outcome.lab_time_s > 0
