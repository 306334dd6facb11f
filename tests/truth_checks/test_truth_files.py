"""The truth suite's files: deterministic, complete, and importable by pianobot's importers."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from cli_runner import invoke_cli

from pianobot.io.importers import import_keystroke_log, import_mocap
from pianobot.io.keystroke_log import read_keystroke_log
from pianobot.store import load_run
from tests.truth import (
    FORMS,
    GridSchedule,
    Materialised,
    control_scenarios,
    effect_scenarios,
    full_suite,
    materialise,
    scenario,
    small_suite,
    variant_suite,
    with_seed,
)
from tests.truth.__main__ import main as truth_main
from tests.truth.arm import PressCommand
from tests.truth.ctrl_log import Stroke, assemble
from tests.truth.readout import NoteEvent, Piano

SMALL_GRID = GridSchedule(accelerations_mps2=(0.1, 1.0), speeds_mps=(0.02, 0.08),
                          depths_m=(0.02, 0.04))  # fmt: skip


USED = ("mocap-clean-light-finger-shallow-0", "midi-clean-light-finger-0",
        "mocap-keybed-power_law-strong")  # fmt: skip


@pytest.fixture(scope="module")
def small(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Materialised]:
    """The small suite's scenarios these tests read (all of them are in `small_suite()`)."""
    out = tmp_path_factory.mktemp("truth")
    chosen = [s for s in small_suite() if s.name in USED]
    assert len(chosen) == len(USED)
    return {m.scenario.name: m for m in (materialise(s, out) for s in chosen)}


def _files(made: Materialised) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in made.folder.iterdir()}


def test_same_scenario_and_seed_give_the_same_bytes(tmp_path: Path) -> None:
    take = scenario("mocap-clean-light-finger-hover-2")
    log = replace(scenario("midi-velocity_curve-rational-strong"), grid=SMALL_GRID)
    for s in (take, log):
        a, b = materialise(s, tmp_path / "a"), materialise(s, tmp_path / "b")
        assert _files(a) == _files(b)
    first = (tmp_path / "a" / take.name / "take.csv").read_bytes()
    other = materialise(with_seed(take, 12345), tmp_path / "c")
    assert (other.folder / "take.csv").read_bytes() != first


def test_catalogue_covers_forms_strengths_and_controls() -> None:
    effects, controls = effect_scenarios(), control_scenarios()
    names = [s.name for s in full_suite()]
    assert len(names) == len(set(names))
    assert len({s.seed for s in full_suite()}) == len(names)
    forms = {(s.kind, s.effect.kind, s.effect.form) for s in effects if s.effect}
    assert len(forms) >= 10
    for kind, k, f in forms:
        strengths = {
            s.strength
            for s in effects
            if s.effect and (s.kind, s.effect.kind, s.effect.form) == (kind, k, f)
        }
        assert strengths == {"strong", "weak"}, (kind, k, f)
    equal = {FORMS[(k, f)].equals_candidate for _, k, f in forms}
    assert equal == {True, False}
    assert len({s.effect.info.family for s in effects if s.effect}) >= 5
    assert len(controls) >= 10 and all(s.effect is None for s in controls)
    assert len({s.base for s in controls}) >= 3 and {s.kind for s in controls} == {"mocap", "midi"}
    assert len({s.seed for s in controls}) == len(controls)


def test_truth_json_says_what_the_answer_is(small: dict[str, Materialised]) -> None:
    made = small["mocap-keybed-power_law-strong"]
    truth = json.loads(made.files["truth"].read_text())
    assert truth["family"] == "key_stop" and truth["effect"] == "keybed"
    assert truth["form"] == "power_law" and truth["form_equals_candidate"] is False
    assert truth["strength"] == "strong" and truth["seed"] == made.scenario.seed
    assert set(truth["accepted_effects"]) == {"keybed", "letoff"}
    assert truth["effect_params"]["exponent"] == 2.5
    assert truth["base"]["k0_npm"] != truth["base"]["k1_npm"]
    assert len(truth["presses"]) == 24 and truth["vacuum_kpa"] == made.scenario.vacuum_kpa
    assert truth["effect_size"]["key_rms_m"] > 1e-4
    assert truth["outcome"]["unresolved_steps"] == 0
    clean = json.loads(small["mocap-clean-light-finger-shallow-0"].files["truth"].read_text())
    assert clean["family"] == "none" and clean["effect"] is None and clean["form"] is None
    assert clean["strength"] == "clean" and clean["accepted_effects"] == []
    assert "effect_size" not in clean


def test_takes_import_as_24_keystrokes_with_the_right_roles(
    small: dict[str, Materialised], tmp_path: Path
) -> None:
    for name in ("mocap-clean-light-finger-shallow-0", "mocap-keybed-power_law-strong"):
        made = small[name]
        result = import_mocap(made.files["take"], tmp_path, vacuum_kpa=made.scenario.vacuum_kpa)
        assert result.trials == 24
        roles = made.truth["mocap"]["roles"]
        assert result.extra["roles"] == {r: roles[r] for r in ("arm", "fingertip", "key")}
        trials = load_run(result.run_id, tmp_path).trials.sort_values("index")
        commanded = made.truth["presses"]
        starts = np.array([p["t_start_s"] for p in commanded])
        # pianobot's segmentation finds every press (its motion start is a little late: it
        # waits for the displacement to clear a noise threshold)
        assert np.all(np.abs(trials["t_start_s"].to_numpy() - starts) < 0.25)
        depth = commanded[0]["depth_m"] + commanded[0]["distance_m"]
        assert np.allclose(trials["arm_travel_m"], depth, rtol=0.1)


def test_a_take_captured_at_240_hz_says_so_and_imports_at_that_rate(tmp_path: Path) -> None:
    made = materialise(scenario("variant-clean-240hz"), tmp_path / "files")
    header = made.files["take"].read_text(encoding="utf-8").splitlines()[0].split(",")
    assert header[header.index("Capture Frame Rate") + 1] == "240.000000"
    assert made.truth["mocap"]["frame_rate_hz"] == 240.0
    result = import_mocap(made.files["take"], tmp_path / "data", vacuum_kpa=made.scenario.vacuum_kpa)
    assert result.trials == 24
    samples = load_run(result.run_id, tmp_path / "data").samples
    one = samples[samples.trial_id == samples.trial_id.iloc[0]]
    assert np.median(np.diff(one.t_s.to_numpy())) == pytest.approx(1 / 240, rel=1e-3)  # Motive writes ms


def test_variants_are_suite_takes_recorded_otherwise() -> None:
    by_name = {s.name: s for s in full_suite()}
    variants = variant_suite()
    assert len(variants) == len({v.name for v in variants}) == 23
    assert {v.frame_rate_hz for v in variants} == {100.0, 120.0, 240.0}
    assert sum(v.effect is None for v in variants) == 8
    # One moves its hidden effect to another finger and key.
    source = by_name["mocap-key_friction-stribeck-strong"]
    moved = next(v for v in variants if v.name == "variant-friction-stribeck-strong-stiff-key")
    assert (moved.effect, moved.take) == (source.effect, source.take)
    assert (source.base, source.vacuum_kpa) != (moved.base, moved.vacuum_kpa) == ("stiff-key", -60.0)
    # One moves an effect's parameter: a stop within a resting finger's reach.
    reached = next(v for v in variants if v.name == "variant-keybed-hunt_crossley-strong-resting")
    assert reached.effect is not None and reached.effect.params["depth_m"] == 0.0008
    assert reached.take.key_target_m is None and reached.take.distance_m == 0.0
    # One records a weak felt rail from a finger that hovers before each press.
    hovering = next(v for v in variants if v.name == "variant-preload-felt_rail-weak-hover")
    assert hovering.take.distance_m == 0.005 and by_name["mocap-key_preload-felt_rail-weak"].take.distance_m == 0.0
    # One plays a clean log on a soft piano: its full-scale speed, nothing else.
    soft = next(v for v in variants if v.name == "variant-midi-clean-soft-piano")
    assert soft.piano.full_scale_mps == 0.6 != by_name["midi-clean-light-key-0"].piano.full_scale_mps
    assert replace(soft.piano, full_scale_mps=0.08) == by_name["midi-clean-light-key-0"].piano
    assert {v.kind for v in variants} == {"mocap", "midi"}
    assert all(v.name not in by_name and v.seed not in {s.seed for s in by_name.values()} for v in variants)
    with pytest.raises(ValueError, match="does not divide"):
        replace(variants[0], frame_rate_hz=180.0)


def test_a_mocap_clock_effect_measures_its_size_when_it_moves_the_last_frame(tmp_path: Path) -> None:
    """A clock offset shifts which true instant each frame shows: on this base and seed the take
    without the effect has one frame more than the take with it. The effect's size is measured
    over the frames both have (it raised a shape mismatch before)."""
    s = scenario("mocap-mocap_delay-offset-weak")
    made = materialise(replace(s, base="soft-key", vacuum_kpa=-40.0, seed=560_409_910), tmp_path / "files")
    size = made.truth["effect_size"]
    assert all(math.isfinite(v) for v in size.values()) and 0.0 < size["key_rms_m"] < 1e-3


def test_logs_import_with_every_outcome_on_its_line(
    small: dict[str, Materialised], tmp_path: Path
) -> None:
    made = small["midi-clean-light-finger-0"]
    result = import_keystroke_log(made.files["log"], tmp_path)
    assert result.trials == 135 and result.extra["layout"] == "soft-2022"
    strokes = made.truth["strokes"]
    assert (
        result.silent
        == sum(s["on_velocity"] is None for s in strokes)
        == made.truth["outcome"]["silent"]
    )
    assert 0 < result.silent < 135
    trials = load_run(result.run_id, tmp_path).trials.sort_values("index")
    want = [math.nan if s["on_velocity"] is None else s["on_velocity"] for s in strokes]
    assert np.array_equal(trials["on_velocity"].to_numpy(), np.array(want, float), equal_nan=True)
    presses = made.truth["presses"]
    for column, key in (("acceleration_mps2", "acceleration_mps2"), ("depth_m", "depth_m"),
                        ("down_velocity_mps", "down_velocity_mps")):  # fmt: skip
        assert np.allclose(trials[column], [p[key] for p in presses])
    assert (trials["vacuum_kpa"] == made.scenario.vacuum_kpa).all()


def test_late_events_spill_into_the_next_line_and_are_put_back_by_time(tmp_path: Path) -> None:
    """A note-off after the script's read is printed on the next line, as in the real logs."""
    press = PressCommand(0.0, 0.05, 1.0, 0.03, 0.05, 0.0, 0.05)
    late = Stroke(
        press,
        (NoteEvent(1.2, "note_on", 10, 0.1), NoteEvent(press.t_end_s + 0.5, "note_off", 5, 0.1)),
        0.006,
        0.05,
        2,
        0,
    )
    quiet = Stroke(press, (), 0.003, 0.05, 2, 0)
    session = assemble([late, quiet, quiet], -60.0, 45.0, Piano(), np.random.default_rng(0),
                       5.0, 1.0, 0.0)  # fmt: skip
    lines = [eval(line, {}) for line in session.lines]  # the lines are plain literals
    assert [len(r["midi"]) for r in lines] == [1, 1, 0]
    path = tmp_path / "soft_60_angle_45.txt"
    path.write_text("\n".join(session.lines) + "\n")
    log = read_keystroke_log(path)
    assert log.trials["on_velocity"].tolist()[0] == 10
    assert log.trials["midi_hold_s"].iloc[0] == pytest.approx(press.t_end_s + 0.5 - 1.2, abs=0.003)
    assert log.trials["status"].tolist()[1:] == ["silent", "silent"]


def test_command_line_writes_and_pianobot_cli_imports(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    assert truth_main([str(tmp_path / "out"), "--only", "mocap-clean-light-finger-hover-2"]) == 0
    take = tmp_path / "out" / "mocap-clean-light-finger-hover-2" / "take.csv"
    assert take.is_file()
    capsys.readouterr()
    code, out, err = invoke_cli(["import", "mocap", str(take), "--vacuum-kpa", "-40", "--data",
                                 str(tmp_path / "data"), "--json"], capsys, monkeypatch)  # fmt: skip
    assert code == 0, err
    assert json.loads(out)["trials"] == 24
    assert truth_main([str(tmp_path), "--only", "no-such-scenario"]) == 2
