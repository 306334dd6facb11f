"""Plans: expansion counts, determinism, stable trial ids, ordering, lab time, summaries."""

from __future__ import annotations

import json
import math
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from pianobot.errors import InputError
from pianobot.physics.trajectory import press_duration_s
from pianobot.plan import (
    PLAN_COLUMNS,
    Trial,
    check_envelope,
    estimate_lab_time_s,
    expand,
    lab_time,
    move_durations_s,
    plan_frame,
    summarize,
)
from pianobot.spec import ExperimentSpec, RigSpec, load_rig_for, load_spec

REPO = Path(__file__).resolve().parents[2]
EXAMPLES = sorted((REPO / "experiments").glob("*.yaml"))


def make_spec(sweep: dict[str, Any], **top: Any) -> ExperimentSpec:
    """A spec built in code (no envelope check: that is `expand(spec, rig)`'s job here)."""
    return ExperimentSpec.model_validate({"name": "t", "finger": "soft", **top, "sweep": sweep})


GRID: dict[str, Any] = {
    "mode": "grid",
    "params": {
        "vacuum_kpa": [0, -20, -40],
        "down_velocity_mps": {"start": 0.01, "stop": 0.06, "num": 6},
        "depth_m": [0.02, 0.03],
    },
    "fixed": {"distance_m": 0.05},
}


def with_(base: dict[str, Any], **changes: Any) -> dict[str, Any]:
    copy: dict[str, Any] = json.loads(json.dumps(base))
    copy.update(changes)
    return copy


def ids(trials: list[Trial]) -> list[str]:
    return [t.trial_id for t in trials]


# ---- expansion -------------------------------------------------------------------------------


def test_grid_count_defaults_and_nesting() -> None:
    trials = expand(make_spec(with_(GRID, repeats=2)))
    assert len(trials) == 3 * 6 * 2 * 2
    first = trials[0]
    assert (first.note, first.acceleration_mps2, first.hold_s, first.finger_angle_deg) == (57, 0.5, 0.0, 0.0)
    assert all(t.up_velocity_mps == t.down_velocity_mps for t in trials)
    # as-listed: the first listed parameter is outermost, repeats back to back.
    assert [t.vacuum_kpa for t in trials[:24]] == [0.0] * 24
    assert [t.repeat for t in trials[:4]] == [0, 1, 0, 1]
    assert [t.depth_m for t in trials[:4]] == [0.02, 0.02, 0.03, 0.03]
    assert [t.index for t in trials] == list(range(len(trials)))
    assert trials[2].down_velocity_mps == 0.01 and trials[4].down_velocity_mps == 0.02


def test_listing_order_sets_the_nesting() -> None:
    params = {"depth_m": [0.02, 0.03], "vacuum_kpa": [0, -20], "down_velocity_mps": [0.03]}
    trials = expand(make_spec(with_(GRID, params=params)))
    assert [t.depth_m for t in trials] == [0.02, 0.02, 0.03, 0.03]
    assert [t.vacuum_kpa for t in trials] == [0.0, -20.0, 0.0, -20.0]


def test_explicit_up_velocity_and_note() -> None:
    spec = make_spec(with_(GRID, fixed={"up_velocity_mps": 0.2, "hold_s": 0.5}), note=60)
    trials = expand(spec)
    assert {t.up_velocity_mps for t in trials} == {0.2}
    assert {(t.note, t.hold_s, t.distance_m) for t in trials} == {(60, 0.5, 0.05)}


@pytest.mark.parametrize("mode", ["random", "lhs"])
def test_sampled_counts_ranges_and_determinism(mode: str) -> None:
    sweep = {
        "mode": mode, "samples": 50, "seed": 4, "repeats": 2,
        "params": {
            "down_velocity_mps": {"low": 0.01, "high": 0.06},
            "depth_m": [0.02, 0.025, 0.03],
            "note": {"low": 60, "high": 64},
        },
    }
    trials = expand(make_spec(sweep))
    assert len(trials) == 100
    assert all(0.01 <= t.down_velocity_mps <= 0.06 for t in trials)
    assert {t.depth_m for t in trials} <= {0.02, 0.025, 0.03}
    assert {t.note for t in trials} <= set(range(60, 65)) and all(isinstance(t.note, int) for t in trials)
    assert expand(make_spec(sweep)) == trials
    other = expand(make_spec(with_(sweep, seed=5)))
    assert [t.down_velocity_mps for t in other] != [t.down_velocity_mps for t in trials]


def test_lhs_puts_one_sample_in_every_stratum() -> None:
    n = 40
    sweep = {
        "mode": "lhs", "samples": n, "seed": 1,
        "params": {
            "down_velocity_mps": {"low": 0.01, "high": 0.05},
            "vacuum_kpa": [0, -20, -40, -60],
            "depth_m": {"low": 0.02, "high": 0.03},
        },
        "fixed": {},
    }
    trials = expand(make_spec(sweep))
    strata = sorted(int((t.down_velocity_mps - 0.01) / 0.04 * n) for t in trials)
    assert strata == list(range(n))
    assert Counter(t.vacuum_kpa for t in trials) == {0.0: 10, -20.0: 10, -40.0: 10, -60.0: 10}


def test_coinciding_random_samples_keep_unique_ids() -> None:
    sweep = {"mode": "random", "samples": 30, "params": {"depth_m": [0.02, 0.03]},
             "fixed": {"down_velocity_mps": 0.03}}
    trials = expand(make_spec(sweep))
    assert len(set(ids(trials))) == 30


# ---- trial ids -------------------------------------------------------------------------------


def test_ids_are_stable_across_files_and_formatting(tmp_path: Path) -> None:
    a = tmp_path / "a.yaml"
    b = tmp_path / "b.yaml"
    a.write_text(yaml.safe_dump({"name": "t", "finger": "soft", "sweep": GRID}))
    explicit = with_(GRID)
    explicit["params"]["down_velocity_mps"] = [0.01, 0.02, 0.03, 0.04, 0.05, 0.06]
    b.write_text("# same experiment, written differently\n" + yaml.safe_dump(
        {"sweep": explicit, "finger": "soft", "name": "t", "rig": "sim", "note": 57}
    ))
    assert ids(expand(load_spec(a))) == ids(expand(load_spec(b)))


def test_float_repr_noise_does_not_change_ids() -> None:
    clean = with_(GRID, fixed={"distance_m": 0.045})
    noisy = with_(GRID, fixed={"distance_m": 0.045000000000000005})
    assert ids(expand(make_spec(clean))) == ids(expand(make_spec(noisy)))


@pytest.mark.parametrize(
    "change",
    [
        {"fixed": {"distance_m": 0.04}},
        {"repeats": 2},
        {"params": {**GRID["params"], "depth_m": [0.02, 0.031]}},
    ],
    ids=["fixed-value", "repeats", "one-level"],
)
def test_changing_the_spec_changes_ids(change: dict[str, Any]) -> None:
    before = set(ids(expand(make_spec(GRID))))
    after = set(ids(expand(make_spec(with_(GRID, **change)))))
    assert before.isdisjoint(after)


def test_ids_follow_the_trial_not_its_position() -> None:
    listed = expand(make_spec(GRID))
    shuffled = expand(make_spec(with_(GRID, order="shuffled")))
    # The order is part of the spec, so ids differ between the two specs, but within one spec
    # the id depends on parameters + repeat: equal points in two repeats differ only by repeat.
    assert len(set(ids(shuffled))) == len(shuffled)
    assert len(set(ids(listed))) == len(listed)
    repeated = expand(make_spec(with_(GRID, repeats=3)))
    by_point = Counter(tuple(sorted(t.parameters().items())) for t in repeated)
    assert set(by_point.values()) == {3}


# ---- ordering --------------------------------------------------------------------------------


def test_shuffled_is_a_seeded_permutation() -> None:
    listed = expand(make_spec(GRID))
    shuffled = expand(make_spec(with_(GRID, order="shuffled")))
    assert Counter(map(_key, shuffled)) == Counter(map(_key, listed))
    assert list(map(_key, shuffled)) != list(map(_key, listed))
    assert expand(make_spec(with_(GRID, order="shuffled"))) == shuffled
    reseeded = expand(make_spec(with_(GRID, order="shuffled", seed=9)))
    assert list(map(_key, reseeded)) != list(map(_key, shuffled))


def _key(t: Trial) -> tuple[Any, ...]:
    return (*t.parameters().values(), t.repeat)


def _runs(values: list[float]) -> list[float]:
    """Consecutive distinct values (a block structure shows as each value appearing once)."""
    return [v for i, v in enumerate(values) if i == 0 or values[i - 1] != v]


def test_blocked_shuffle_keeps_vacuum_blocks_contiguous_in_listed_order() -> None:
    params = {"depth_m": [0.02, 0.03], "vacuum_kpa": [-40, 0, -20],
              "down_velocity_mps": {"start": 0.01, "stop": 0.06, "num": 6}}
    spec = make_spec(with_(GRID, params=params, order="blocked-shuffle", repeats=2))
    trials = expand(spec)
    assert _runs([t.vacuum_kpa for t in trials]) == [-40.0, 0.0, -20.0]
    listed = expand(make_spec(with_(GRID, params=params, repeats=2)))
    assert Counter(map(_key, trials)) == Counter(map(_key, listed))
    block = [t for t in trials if t.vacuum_kpa == -40.0]
    in_listed_order = [t for t in listed if t.vacuum_kpa == -40.0]
    assert list(map(_key, block)) != list(map(_key, in_listed_order))  # shuffled inside
    assert lab_time(trials).vacuum_changes == 3 < lab_time(
        expand(make_spec(with_(GRID, params=params, order="shuffled", repeats=2)))
    ).vacuum_changes


def test_blocked_shuffle_by_two_parameters() -> None:
    params = {"finger_angle_deg": [20, 45], "vacuum_kpa": [0, -40],
              "down_velocity_mps": [0.02, 0.04], "depth_m": [0.02, 0.03]}
    trials = expand(make_spec(with_(GRID, params=params, order="blocked-shuffle",
                                    block_by=["finger_angle_deg", "vacuum_kpa"])))
    pairs = [(t.finger_angle_deg, t.vacuum_kpa) for t in trials]
    assert [p for i, p in enumerate(pairs) if i == 0 or pairs[i - 1] != p] == [
        (20.0, 0.0), (20.0, -40.0), (45.0, 0.0), (45.0, -40.0)
    ]


# ---- rows, frames, safety gate ---------------------------------------------------------------


def test_press_row_and_frame() -> None:
    trials = expand(make_spec(GRID))
    t = trials[5]
    press = t.press()
    assert (press.distance_m, press.depth_m, press.down_velocity_mps, press.up_velocity_mps,
            press.acceleration_mps2, press.hold_s) == (
        t.distance_m, t.depth_m, t.down_velocity_mps, t.up_velocity_mps, t.acceleration_mps2, t.hold_s)
    assert tuple(t.row()) == PLAN_COLUMNS and t.row()["trial_id"] == t.trial_id
    frame = plan_frame(trials)
    assert list(frame.columns) == list(PLAN_COLUMNS) and len(frame) == len(trials)
    assert frame["trial_id"].tolist() == ids(trials)
    assert str(frame["note"].dtype) == "int64" and str(frame["depth_m"].dtype) == "float64"
    empty = plan_frame([])
    assert list(empty.columns) == list(PLAN_COLUMNS) and len(empty) == 0


def test_expand_with_a_rig_refuses_unsafe_trials() -> None:
    unsafe = make_spec(with_(GRID, fixed={"distance_m": 0.05, "hold_s": 5.0}))
    assert len(expand(unsafe)) == 36  # planning alone does not judge
    with pytest.raises(InputError, match="hold_s 5 s is outside") as info:
        expand(unsafe, RigSpec())
    assert info.value.where == "t: trial 0 (hold_s)"
    assert len(expand(make_spec(GRID), RigSpec())) == 36


# ---- lab time --------------------------------------------------------------------------------

QUIET = RigSpec.model_validate({"settle_s": {"after_vacuum_change_s": 0, "between_presses_s": 0}})


def test_lab_time_is_the_sum_of_press_durations_without_pauses() -> None:
    spec = make_spec(with_(GRID, params={"down_velocity_mps": [0.01, 0.05],
                                         "acceleration_mps2": [0.1, 1.0], "depth_m": [0.02]},
                           fixed={"hold_s": 0.3}))
    trials = expand(spec)
    expected = sum(press_duration_s(t.press()) for t in trials)
    assert estimate_lab_time_s(trials, QUIET) == pytest.approx(expected, rel=1e-12)
    # A slow 0.01 m/s press over 7 cm takes at least 2 x 7 s.
    assert expected > 4 * 0.3 + 2 * (2 * 0.07 / 0.01)


def test_lab_time_counts_pauses_vacuum_changes_and_key_moves() -> None:
    rig = RigSpec.model_validate({"settle_s": {"after_vacuum_change_s": 10, "between_presses_s": 0.5}})
    trials = expand(make_spec(GRID))  # vacuum 0 first (no change), then -20, -40
    t = lab_time(trials, rig)
    assert t.vacuum_changes == 2 and t.vacuum_s == 20
    assert t.pauses_s == 0.5 * len(trials)
    assert t.total_s == pytest.approx(estimate_lab_time_s(trials, QUIET) + 20 + 0.5 * len(trials))
    notes = expand(make_spec(with_(GRID, params={**GRID["params"], "note": [57, 69]})))
    moves = lab_time(notes, QUIET)
    changes = sum(a.note != b.note for a, b in zip(notes, notes[1:], strict=False))
    assert moves.key_changes == changes > 0
    presses = sum(press_duration_s(t.press()) for t in notes)
    assert moves.travel_s > 0 and moves.total_s == pytest.approx(presses + moves.travel_s)
    # An octave (7 white keys = 16.45 cm) at 0.1 m/s takes longer than the distance alone.
    assert moves.travel_s / changes > 0.1645 / 0.1


def test_summary_dict_and_text() -> None:
    spec = make_spec(with_(GRID, params={**GRID["params"], "acceleration_mps2": [0.05]},
                           fixed={"distance_m": 0.05}))
    trials = expand(spec)
    violations = check_envelope(trials, spec.finger, RigSpec())
    summary = summarize(spec, trials, violations, RigSpec())
    data = json.loads(json.dumps(summary.to_dict()))
    assert data["trials"] == 36 and data["errors"] == 0
    assert data["coverage"]["down_velocity_mps"] == {"min": 0.01, "max": 0.06, "levels": 6}
    assert data["lab_time"]["total_s"] == pytest.approx(estimate_lab_time_s(trials, RigSpec()))
    assert data["warnings"] == len(data["violations"]) > 0  # slow acceleration: speed not reached
    text = summary.to_text()
    assert "36 trials" in text and "lab time" in text and "warning ×" in text


# ---- the committed examples ------------------------------------------------------------------


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_example_specs_expand_without_errors(path: Path) -> None:
    spec = load_spec(path)
    rig = load_rig_for(spec)
    trials = expand(spec, rig)
    assert trials and len(set(ids(trials))) == len(trials)
    errors = [v for v in check_envelope(trials, spec.finger, rig) if v.severity == "error"]
    assert errors == []


def test_soft_finger_grid_is_the_study_grid() -> None:
    spec = load_spec(REPO / "experiments" / "soft_finger_grid.yaml")
    trials = expand(spec, load_rig_for(spec))
    assert len(trials) == 2025
    assert sorted({t.vacuum_kpa for t in trials}) == [-80, -60, -40, -20, 0]
    speeds = sorted({t.down_velocity_mps for t in trials})
    assert len(speeds) == 15 and speeds[0] == 0.01 and speeds[-1] == 0.08
    assert 0.045 in speeds  # no repr noise: 0.045000000000000005 is cleaned
    assert {t.distance_m for t in trials} == {0.05} and {t.hold_s for t in trials} == {0.0}


def test_quickstart_is_small() -> None:
    spec = load_spec(REPO / "experiments" / "quickstart.yaml")
    assert len(expand(spec)) <= 32 and spec.record == ["midi", "arm", "mocap"]


# ---- properties ------------------------------------------------------------------------------

levels = st.lists(st.integers(1, 50), min_size=1, max_size=4, unique=True)


@settings(max_examples=30, deadline=None)
@given(speeds=levels, depths=st.lists(st.integers(20, 35), min_size=1, max_size=3, unique=True),
       repeats=st.integers(1, 3), order=st.sampled_from(["as-listed", "shuffled", "blocked-shuffle"]),
       seed=st.integers(0, 2**16))
def test_grid_properties(speeds: list[int], depths: list[int], repeats: int, order: str,
                         seed: int) -> None:
    sweep = {"mode": "grid", "order": order, "seed": seed, "repeats": repeats,
             "params": {"down_velocity_mps": [s / 1000 for s in speeds],
                        "depth_m": [d / 1000 for d in depths]}}
    trials = expand(make_spec(sweep))
    assert len(trials) == len(speeds) * len(depths) * repeats
    assert len(set(ids(trials))) == len(trials)
    assert expand(make_spec(sweep)) == trials
    assert sorted(t.repeat for t in trials) == sorted(list(range(repeats)) * len(speeds) * len(depths))
    assert all(math.isfinite(t.down_velocity_mps) for t in trials)


def test_sampled_blocks_follow_the_listed_choices() -> None:
    sweep = {"mode": "lhs", "samples": 30, "seed": 11, "order": "blocked-shuffle",
             "params": {"vacuum_kpa": [-40, 0, -80], "down_velocity_mps": {"low": 0.01, "high": 0.06}},
             "fixed": {"depth_m": 0.03}}
    trials = expand(make_spec(sweep))
    assert _runs([t.vacuum_kpa for t in trials]) == [-40.0, 0.0, -80.0]


def test_blocked_shuffle_without_block_parameters_is_a_shuffle() -> None:
    trials = expand(make_spec(with_(GRID, order="blocked-shuffle", block_by=[])))
    listed = expand(make_spec(GRID))
    assert len(trials) == len(listed)
    assert Counter(map(_key, trials)) == Counter(map(_key, listed))
    assert list(map(_key, trials)) != list(map(_key, listed))


@settings(max_examples=200, deadline=None)
@given(distance=st.floats(0.0, 0.2), v=st.floats(0.001, 1.0), a=st.floats(0.01, 5.0),
       hold=st.floats(0.0, 2.0), up=st.floats(0.001, 1.0), depth=st.floats(0.0, 0.05))
def test_vectorised_durations_match_the_physics(distance: float, v: float, a: float, hold: float,
                                                up: float, depth: float) -> None:
    trial = Trial("x", 0, 0, 57, 0.0, v, up, a, depth, distance, hold, 0.0)
    travel = np.array([distance + depth])
    ours = (move_durations_s(travel, np.array([v]), np.array([a]))[0] + hold
            + move_durations_s(travel, np.array([up]), np.array([a]))[0])
    assert ours == pytest.approx(press_duration_s(trial.press()), rel=1e-9, abs=1e-12)
    assert estimate_lab_time_s([trial], QUIET) == pytest.approx(ours, rel=1e-12)


def test_a_long_duration_reads_at_a_glance_and_a_short_one_is_not_zero() -> None:
    from pianobot.durations import format_long_duration

    # A 16-trial plan refused by --max-trials 10 read "(≈ 0.0 h of lab time)".
    assert format_long_duration(108.0) == "1.8 min"
    assert format_long_duration(3 * 3600.0) == "3.0 h" and format_long_duration(20 * 86400.0) == "20 days"
    assert format_long_duration(float("nan")) == "unknown time"
