"""The safety envelope on planned trials: per-parameter ranges and cross-parameter checks."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pianobot.errors import InputError
from pianobot.physics.trajectory import contact_speed_mps
from pianobot.plan import Trial, Violation, check_envelope, contact_speeds_mps, raise_for_errors
from pianobot.spec import FINGER_ENVELOPES, RigSpec, load_rig

SOFT = Trial(
    trial_id="0" * 16, index=0, repeat=0, note=57, vacuum_kpa=-40.0, down_velocity_mps=0.03,
    up_velocity_mps=0.03, acceleration_mps2=1.0, depth_m=0.03, distance_m=0.05, hold_s=0.0,
    finger_angle_deg=0.0,
)
RIGID = replace(SOFT, vacuum_kpa=0.0, depth_m=0.012, down_velocity_mps=0.1, up_velocity_mps=0.1,
                acceleration_mps2=2.0)


def errors(violations: list[Violation]) -> list[Violation]:
    return [v for v in violations if v.severity == "error"]


def test_safe_trials_pass() -> None:
    assert check_envelope([SOFT], "soft") == []
    assert check_envelope([RIGID], "rigid") == []


@pytest.mark.parametrize(
    ("finger", "change", "parameter", "allowed"),
    [
        ("soft", {"down_velocity_mps": 0.07}, "down_velocity_mps", (0.0, 0.06)),
        ("soft", {"up_velocity_mps": 0.8}, "up_velocity_mps", (0.0, 0.7)),
        ("soft", {"acceleration_mps2": 0.02}, "acceleration_mps2", (0.05, 2.0)),
        ("soft", {"distance_m": 0.06}, "distance_m", (0.0, 0.05)),
        ("soft", {"depth_m": 0.015}, "depth_m", (0.02, 0.035)),
        ("soft", {"hold_s": 2.5}, "hold_s", (0.0, 2.0)),
        ("soft", {"vacuum_kpa": -90.0}, "vacuum_kpa", (-80.0, 0.0)),
        ("rigid", {"down_velocity_mps": 0.005}, "down_velocity_mps", (0.01, 0.5)),
        ("rigid", {"depth_m": 0.005}, "depth_m", (0.008, 0.015)),
        ("rigid", {"vacuum_kpa": -20.0}, "vacuum_kpa", (0.0, 0.0)),
    ],
)
def test_each_parameter_has_its_range(
    finger: str, change: dict[str, float], parameter: str, allowed: tuple[float, float]
) -> None:
    base = SOFT if finger == "soft" else RIGID
    found = errors(check_envelope([replace(base, **change)], finger))  # type: ignore[arg-type]
    assert [(v.parameter, v.allowed) for v in found] == [(parameter, allowed)]
    assert found[0].value == change[parameter]
    assert f"{finger} finger" in found[0].message


def test_depth_past_the_finger_limit_is_a_keybed_violation() -> None:
    [v] = errors(check_envelope([replace(RIGID, depth_m=0.02)], "rigid"))
    assert v.rule == "keybed" and v.parameter == "depth_m"
    assert "10.0 mm past the keybed" in v.message and "cleared for 5.0 mm" in v.message
    [soft] = errors(check_envelope([replace(SOFT, depth_m=0.04)], "soft"))
    assert soft.rule == "keybed" and "30.0 mm past the keybed" in soft.message


def test_rig_file_widens_the_envelope() -> None:
    fast_deep = replace(SOFT, down_velocity_mps=0.08, up_velocity_mps=0.08, depth_m=0.04)
    assert {v.parameter for v in errors(check_envelope([fast_deep], "soft"))} == {
        "down_velocity_mps", "depth_m"
    }
    wide = RigSpec.model_validate(
        {"envelope": {"soft": {"down_velocity_mps": [0, 0.08], "depth_m": [0.02, 0.04]}}}
    )
    assert errors(check_envelope([fast_deep], "soft", wide, rig_label="wide.yaml")) == []
    narrow = RigSpec.model_validate({"envelope": {"soft": {"hold_s": [0, 0]}}})
    [v] = check_envelope([replace(SOFT, hold_s=0.5)], "soft", narrow, rig_label="lab.yaml")
    assert "set by lab.yaml" in v.message


def test_invalid_values_are_bounds_errors() -> None:
    found = errors(check_envelope([replace(SOFT, down_velocity_mps=0.0, note=120)], "soft"))
    assert {(v.parameter, v.rule) for v in found} >= {("down_velocity_mps", "bounds"), ("note", "bounds")}


@pytest.mark.parametrize(
    ("distance_m", "depth_m", "velocity", "accel", "why"),
    [
        (0.05, 0.02, 0.06, 0.05, "already braking"),  # √(2·0.05·0.02) = 0.045 < 0.06
        (0.002, 0.03, 0.05, 0.1, "still accelerating"),  # √(2·0.1·0.002) = 0.02 < 0.05
    ],
)
def test_unreachable_speed_is_a_warning(
    distance_m: float, depth_m: float, velocity: float, accel: float, why: str
) -> None:
    trial = replace(SOFT, distance_m=distance_m, depth_m=depth_m, down_velocity_mps=velocity,
                    up_velocity_mps=velocity, acceleration_mps2=accel)
    [v] = check_envelope([trial], "soft")
    assert (v.severity, v.rule, v.parameter) == ("warning", "reach", "down_velocity_mps")
    reached = contact_speed_mps(trial.press())
    assert v.allowed == (0.0, pytest.approx(reached)) and reached < velocity
    assert why in v.message
    raise_for_errors([v], "spec.yaml")  # warnings never refuse a plan


def test_triangle_profile_peak_limits_the_speed() -> None:
    # Travel 0.05 m at 0.05 m/s²: the triangle peaks at √(a·d) = 0.05 m/s < 0.06.
    trial = replace(SOFT, distance_m=0.03, depth_m=0.02, down_velocity_mps=0.06,
                    up_velocity_mps=0.06, acceleration_mps2=0.05)
    [v] = check_envelope([trial], "soft")
    assert v.allowed[1] <= math.sqrt(0.05 * 0.05) + 1e-12


def test_reachable_speed_gives_no_warning() -> None:
    assert check_envelope([replace(SOFT, acceleration_mps2=2.0)], "soft") == []


def lab_rig(reference_z: float | None) -> RigSpec:
    rig = load_rig("sim").model_dump()
    rig.update(
        kind="ur5",
        ur5={"host": "h", "workspace_min_m": [-1, -1, 0.10], "workspace_max_m": [1, 1, 0.30],
             "reference_pose": None if reference_z is None else [0, 0, reference_z, 0, 0, 0],
             "safe_lift_m": 0.05},
        midi={"port": "piano"},
    )
    return RigSpec.model_validate(rig)


def test_workspace_box_on_a_calibrated_ur5() -> None:
    assert check_envelope([SOFT], "soft", lab_rig(None)) == []  # uncalibrated: nothing to check
    assert check_envelope([SOFT], "soft", lab_rig(0.15)) == []
    [floor] = check_envelope([SOFT], "soft", lab_rig(0.12))  # 0.12 - 0.03 < 0.10
    assert (floor.rule, floor.parameter) == ("workspace", "depth_m") and "floor" in floor.message
    [ceiling] = check_envelope([SOFT], "soft", lab_rig(0.22))  # 0.22 + 0.05 + 0.05 > 0.30
    assert (ceiling.rule, ceiling.parameter) == ("workspace", "distance_m")


def test_violations_are_in_trial_order_and_errors_raise() -> None:
    trials = [replace(SOFT, index=i, trial_id=f"{i:016x}") for i in range(4)]
    trials[3] = replace(trials[3], hold_s=9.0)
    trials[1] = replace(trials[1], depth_m=0.05, distance_m=0.09)
    found = check_envelope(trials, "soft")
    assert [v.index for v in found] == sorted(v.index for v in found)
    assert {v.index for v in found} == {1, 3}
    assert found[0].trial_id == trials[1].trial_id
    with pytest.raises(InputError, match=r"2 more trial violation") as info:
        raise_for_errors(found, "spec.yaml")
    assert info.value.where is not None and info.value.where.startswith("spec.yaml: trial 1")
    assert set(found[0].to_dict()) == {
        "index", "trial_id", "parameter", "value", "allowed", "message", "severity", "rule"
    }


def inside(finger: str, name: str) -> st.SearchStrategy[float]:
    limits = FINGER_ENVELOPES[finger][name]  # type: ignore[index]
    low = max(limits.low, 0.001) if name.endswith("velocity_mps") else limits.low
    return st.floats(low, limits.high, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_anything_inside_the_envelope_has_no_errors(data: st.DataObject) -> None:
    finger = data.draw(st.sampled_from(["soft", "rigid"]))
    values = {name: data.draw(inside(finger, name)) for name in FINGER_ENVELOPES[finger]}  # type: ignore[index]
    trial = replace(SOFT, **values)
    assert errors(check_envelope([trial], finger)) == []  # type: ignore[arg-type]


@settings(max_examples=200, deadline=None)
@given(distance=st.floats(0.0, 0.2), depth=st.floats(0.0, 0.05), v=st.floats(0.001, 1.0),
       a=st.floats(0.01, 5.0))
def test_vectorised_contact_speed_matches_the_physics(
    distance: float, depth: float, v: float, a: float
) -> None:
    trial = replace(SOFT, distance_m=distance, depth_m=depth, down_velocity_mps=v, acceleration_mps2=a)
    ours = contact_speeds_mps(np.array([distance]), np.array([depth]), np.array([v]), np.array([a]))
    # abs: physics forms (distance + depth) - distance, which loses a tiny depth to rounding
    # (√(2·a·ε·travel) ≈ 1e-8 m/s); ours uses the depth itself.
    assert ours[0] == pytest.approx(contact_speed_mps(trial.press()), rel=1e-9, abs=1e-7)
