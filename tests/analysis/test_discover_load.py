"""The one store loader: trajectories, commanded presses and MIDI into one keystroke batch."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import own_world as ow
import pandas as pd
import pytest

from pianobot.analysis.discover.run import resolve_model
from pianobot.analysis.greybox.load import load_keystrokes
from pianobot.analysis.greybox.split import holdout_indices
from pianobot.errors import InputError
from pianobot.physics.model import KeystrokeModel
from pianobot.store import RunWriter


def test_a_stored_run_loads_with_its_command_and_midi(data_dir: Path) -> None:
    scenario = ow.reduced(ow.control("clean", seed=1), n_speeds=3)
    batch = load_keystrokes([ow.write_run(scenario, data_dir)], data_dir).batch
    assert batch.n == 9 and batch.has_motion and batch.has_midi and batch.arm_source == "arm"
    press = batch.press(0)
    assert press.depth_m == 0.040 and press.distance_m == 0.003 and press.acceleration_mps2 == 1.0
    assert np.isfinite(batch.on_velocity[batch.sounded == 1.0]).all()
    train, held = holdout_indices(batch)
    assert held.size == 3 and set(np.abs(batch.vacuum_kpa[held])) == {20.0, 40.0, 60.0}


def _take(data_dir: Path, vacuum: float | None) -> str:
    trials = pd.DataFrame({"trial_id": ["a", "b"], "index": [0, 1], "attempt": [1, 1], "status": ["ok", "ok"],
                           "vacuum_kpa": [vacuum, vacuum], "down_velocity_mps": [np.nan, np.nan],
                           "arm_speed_mps": [0.01, 0.02], "arm_travel_m": [0.007, 0.007]})
    t = np.arange(-0.1, 1.0, 1 / 120)
    ramp = np.clip(0.01 * t, 0, 0.007)
    samples = pd.concat(pd.DataFrame({"trial_id": tid, "source": "mocap", "t_s": t, "x0_m": 0.5 + ramp,
                                      "x1_m": 0.4 + 0.8 * ramp, "x2_m": 0.3 + 0.5 * ramp}) for tid in ("a", "b"))
    writer = RunWriter.create(data_dir, name="take", kind="import", meta={}, plan=None)
    writer.append(trials, samples)
    writer.finish("completed")
    return writer.run_id


def test_an_imported_take_states_what_it_derived(data_dir: Path) -> None:
    run_id = _take(data_dir, None)
    with pytest.raises(InputError, match="--vacuum-kpa"):
        load_keystrokes([run_id], data_dir)
    loaded = load_keystrokes([run_id], data_dir, vacuum_kpa=-40.0)
    batch = loaded.batch
    assert list(batch.vacuum_kpa) == [-40.0, -40.0] and batch.arm_source == "mocap"
    assert np.isnan(batch.acceleration_mps2).all()  # not recorded: never silently assumed
    with pytest.raises(ValueError, match="acceleration"):
        batch.press(0)
    assert batch.press(0, acceleration_mps2=1.0).depth_m == pytest.approx(0.007)
    assert not batch.has_midi  # no MIDI recorded at all
    assert np.nanmax(np.abs(batch.x2_m[:, :10])) < 1e-9  # absolute heights referenced to rest
    assert {"acceleration not recorded", "depth taken from the measured arm travel",
            "down speed taken from the measured arm speed"} <= set(loaded.notes)


def test_resolve_model(tmp_path: Path) -> None:
    assert resolve_model("study") == KeystrokeModel.study()
    with pytest.raises(InputError):
        resolve_model(str(tmp_path / "missing.json"))


def test_a_batch_press_follows_the_parameter_table_and_the_drive_reuses_it() -> None:
    """An unrecorded or impossible up velocity is the down velocity, an unrecorded hold the
    table's default; the commanded drive rebuilds its presses only for another acceleration."""
    from pianobot.analysis.greybox.commanded import Commanded
    from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
    from pianobot.physics.trajectory import Press
    from pianobot.spec.parameters import PARAMETERS

    n = 3
    batch = KeystrokeBatch(("a", "b", "c"), np.full(n, -40.0), np.zeros(0), np.zeros((n, 0)), np.zeros((n, 0)),
                           np.zeros((n, 0)), down_velocity_mps=np.array([0.05, 0.06, 0.07]),
                           up_velocity_mps=np.array([np.nan, 0.0, 0.2]), acceleration_mps2=np.array([1.0, np.nan, 2.0]),
                           depth_m=np.full(n, 0.01), hold_s=np.array([np.nan, 0.1, 0.2]))
    assert [batch.press(i, 0.5).up_velocity_mps for i in range(n)] == [0.05, 0.06, 0.2]
    assert batch.press(0).hold_s == PARAMETERS["hold_s"].default
    assert batch.press(1, 0.5) == Press(distance_m=0.0, depth_m=0.01, down_velocity_mps=0.06, up_velocity_mps=0.06,
                                        acceleration_mps2=0.5, hold_s=0.1)
    drive = Commanded(batch)
    first = drive.presses(0.5)
    assert all(a is b for a, b in zip(drive.presses(0.5), first, strict=True))  # reused
    other = drive.presses(0.8)
    assert other[1].acceleration_mps2 == 0.8 and other[0] == first[0] and other[1] is not first[1]


def _hover_take(data_dir: Path, hovers_m: list[float]) -> str:
    """A take without its distances: the fingertip moves with the arm until it has travelled
    each keystroke's hover, then the key moves and the finger compresses."""
    ids = [f"k{i}" for i in range(len(hovers_m))]
    trials = pd.DataFrame({"trial_id": ids, "index": range(len(ids)), "attempt": 1, "status": "ok",
                           "vacuum_kpa": -40.0, "down_velocity_mps": np.nan, "arm_speed_mps": 0.01,
                           "arm_travel_m": 0.014})
    t = np.arange(-0.1, 1.6, 1 / 120)
    ramp = np.clip(0.01 * t, 0, 0.014)
    samples = pd.concat(pd.DataFrame({"trial_id": tid, "source": "mocap", "t_s": t, "x0_m": 0.5 + ramp,
                                      "x1_m": 0.4 + ramp - 0.2 * np.maximum(ramp - h, 0.0),
                                      "x2_m": 0.3 + 0.8 * np.maximum(ramp - h, 0.0)})
                        for tid, h in zip(ids, hovers_m, strict=True))
    writer = RunWriter.create(data_dir, name="hover", kind="import", meta={}, plan=None)
    writer.append(trials, samples)
    writer.finish("completed")
    return writer.run_id


@pytest.mark.parametrize(("hovers_mm", "one"), [([4.8, 5.0, 5.2, 5.4, 5.7, 6.1], True),
                                                 ([2.0, 3.0, 5.0, 7.0, 9.0, 11.0], False)])
def test_a_take_without_its_distances_gets_one_hover_where_its_travels_agree(
        data_dir: Path, hovers_mm: list[float], one: bool) -> None:
    """Travels that differ by the pad's compression at key onset (more at speed) are one hover,
    their median; a hover swept within the take stays per keystroke."""
    loaded = load_keystrokes([_hover_take(data_dir, [1e-3 * h for h in hovers_mm])], data_dir)
    distance = loaded.batch.distance_m
    travel = np.asarray(hovers_mm) * 1e-3
    if one:
        assert np.all(distance == distance[0]) and abs(distance[0] - np.median(travel)) < 1e-4
        assert any("one hover for the take" in note for note in loaded.notes)
    else:
        assert np.all(np.abs(distance - travel) < 1e-4)
        assert any("per keystroke" in note for note in loaded.notes)


def test_a_midi_only_run_beside_a_take_is_said_to_be_left_out(data_dir: Path) -> None:
    # identify and discover on a take and a keystroke log together dropped the log in silence.
    from _synthetic_runs import linear_keystrokes, sounded_trials, write_run

    from pianobot.physics.msd import MSDParams

    take = write_run(data_dir, *linear_keystrokes(MSDParams(), seed=3), name="take")
    log = write_run(data_dir, sounded_trials(0), None, name="log")
    loaded = load_keystrokes([take, log], data_dir, need_motion=True)
    assert all(t.startswith(f"{take}/") for t in loaded.batch.trial_id)
    assert any(f"run {log} has no key trajectories" in note and "left out" in note for note in loaded.notes)
    assert not any("left out" in note for note in load_keystrokes([take], data_dir, need_motion=True).notes)


def _levels(*values_um: float) -> np.ndarray:
    return np.asarray(values_um, dtype=float) * 1e-6


def test_a_key_left_down_and_creeping_back_between_presses_is_read_as_held() -> None:
    """Key levels (µm below the take's highest) before and after each press. A key whose
    friction cannot hold it still is left down by each press and rises part of the way back
    before the next (an independent tanh-friction take: 226 µm after a press, 68 µm before the
    next): its spring is still loaded when the next press starts. A marker or the arm's pose
    wanders both ways between presses (zzz40's levels: the key "sinks" 25-35 µm between presses
    and ends 75 µm above its highest level before a press): taken at rest."""
    from pianobot.analysis.greybox.load import _left_by_presses

    before = _levels(0, 68, 12, 15, 51, 35, 53, 22, 11, 13)
    after = _levels(226, 34, 34, 176, 113, 172, 70, 32, 32, 32)
    assert _left_by_presses(before, after)
    # The same levels, left where the presses left them: the rule of a key that sticks.
    assert _left_by_presses(np.concatenate([[0.0], after[:-1]]), after)
    wander_before = _levels(16, 25, 35, 22, 13, 41, 38, 47, 40, 40, 9, 0, 12)
    wander_after = _levels(27, 37, 27, -12, 6, 21, 5, -15, -19, -28, -75, -55, -30)
    assert not _left_by_presses(wander_before, wander_after)
    # A key that drifts down between presses is not relaxing either, however it moved in them.
    assert not _left_by_presses(_levels(0, 40, 80, 120, 160), _levels(20, 60, 100, 140, 180))
    # Nor one that barely moves (within the marker's noise): nothing was left down.
    assert not _left_by_presses(_levels(0, 5, 3, 8, 2), _levels(9, 12, 10, 14, 9))
