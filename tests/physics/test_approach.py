"""Two-segment presses: the fast approach and retract leave the keystroke unchanged.

The arm's side is exact kinematics (checked against `sample_presses` of the spec's press); the
finger's side is physics (checked in the simulated world: contact speed and the key's response
of a fast press match the as-specified press within the world's noise).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pianobot.physics.approach import (
    MIN_FAST_MOVE_M,
    ApproachSettings,
    fast_press,
    plan_fast_moves,
)
from pianobot.physics.effects import Effects
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.simulate import simulate_presses
from pianobot.physics.trajectory import (
    Press,
    check_press,
    contact_speed_mps,
    contact_time_s,
    press_duration_s,
    press_timing,
    sample_presses,
)
from pianobot.physics.world import World

SETTINGS = ApproachSettings()


def _arm(press: Press, t_s: np.ndarray) -> np.ndarray:
    x, _ = sample_presses([press], t_s)
    return x[0]


@settings(deadline=None, max_examples=60)  # no wall-clock limits: the machine is shared
@given(
    distance=st.floats(0.005, 0.1),
    depth=st.floats(0.002, 0.04),
    v=st.floats(0.005, 0.3),
    v_up=st.floats(0.005, 0.3),
    a=st.floats(0.05, 2.0),
    settle=st.floats(0.0, 2.0),
    clearance=st.floats(0.001, 0.01),
)
def test_fast_press_moves_exactly_as_specified_around_the_keystroke(
    distance: float, depth: float, v: float, v_up: float, a: float, settle: float, clearance: float
) -> None:
    spec = Press(distance, depth, v, v_up, a)
    plan = ApproachSettings(velocity_mps=0.3, acceleration_mps2=1.5, clearance_m=clearance,
                            settle_s=settle)
    fast = fast_press(spec, plan)
    assume(fast.two_segment)
    check_press(fast)
    # Same contact speed, never slower overall, and the fast moves stay clear of the key.
    assert contact_speed_mps(fast) == pytest.approx(contact_speed_mps(spec), rel=1e-9, abs=1e-12)
    assert press_duration_s(fast) < press_duration_s(spec)
    assert fast.approach_m <= distance - clearance + 1e-12
    assert fast.retract_m <= distance - clearance + 1e-12
    # From `settle` before contact until the fingertip is `clearance` above the key on the way
    # up, the arm is where the spec's press has it (time-shifted by the approach's saving).
    shift = contact_time_s(spec) - contact_time_s(fast)
    spec_timing = press_timing(spec)
    t = np.linspace(max(contact_time_s(spec) - settle, 0.0), spec_timing.t_end_s, 4001)
    x_spec = _arm(spec, t)
    x_fast = _arm(fast, t - shift)
    kept = (t <= spec_timing.t_hold_end_s) | (x_spec >= distance - clearance)
    kept &= np.cumsum(~kept) == 0  # up to the first sample that leaves the kept stretch
    assert np.max(np.abs(x_fast[kept] - x_spec[kept])) < 1e-9


def test_the_shortcut_condition_is_the_run_up_to_cruise_or_the_braking_depth() -> None:
    """Without settling, the spec-speed move may start min(v²/(2a), depth) above contact."""
    plan = ApproachSettings(clearance_m=0.001, settle_s=0.0)
    cruising = Press(0.05, 0.03, 0.05, 0.05, 0.5)  # v²/(2a) = 2.5 mm < depth: cruising at contact
    braking = Press(0.05, 0.005, 0.08, 0.08, 0.1)  # v²/(2a) = 32 mm > depth: braking at contact
    for press, needed in ((cruising, 0.05**2 / (2 * 0.5)), (braking, 0.005)):
        fast = fast_press(press, plan)
        assert fast.approach_m == pytest.approx(press.distance_m - needed, abs=1e-12)
        assert contact_speed_mps(fast) == pytest.approx(contact_speed_mps(press), rel=1e-12)
        # A millimetre later start would meet the key in another state.
        late = Press(**{**fast.__dict__, "approach_m": fast.approach_m + 1e-3})
        assert contact_speed_mps(late) != pytest.approx(contact_speed_mps(press), rel=1e-3)


def test_no_shortcut_while_the_arm_still_accelerates_at_contact() -> None:
    press = Press(0.01, 0.03, 0.3, 0.3, 0.5)  # v²/(2a) = 90 mm > 10 mm run-up
    moves = plan_fast_moves(press.distance_m, press.depth_m, 0.3, 0.3, 0.5,
                            ApproachSettings(settle_s=0.0))
    assert moves.approach_m[0] == 0.0
    assert fast_press(press, SETTINGS).approach_m == 0.0


def test_plain_presses_are_unchanged_and_invalid_fast_moves_are_refused() -> None:
    press = Press(0.05, 0.03, 0.02, 0.02, 0.5)
    assert not press.two_segment and press.as_specified() == press
    timing = press_timing(press)
    assert timing.approach.duration_s == 0.0 and timing.retract.duration_s == 0.0
    assert timing.t_lifted_s == timing.t_end_s and timing.travel_m == pytest.approx(0.08)
    for bad in ({"approach_m": 0.05}, {"approach_m": -0.01}, {"retract_m": 0.06},
                {"approach_m": 0.01, "travel_velocity_mps": 0.0}):
        with pytest.raises(ValueError):
            check_press(Press(0.05, 0.03, 0.02, 0.02, 0.5, **bad))  # type: ignore[arg-type]
    # Too short to be worth a second move: nothing planned.
    tiny = Press(0.002, 0.03, 0.02, 0.02, 0.5)
    assert fast_press(tiny, ApproachSettings(clearance_m=0.001, settle_s=0.0)).approach_m == 0.0
    assert MIN_FAST_MOVE_M > 0


def test_the_simulator_drives_the_arm_along_all_four_moves() -> None:
    model = KeystrokeModel(effects=Effects.from_dict({"arm_acceleration": {}}))
    presses = [Press(0.05, 0.03, v, v, 0.5) for v in (0.01, 0.03)]
    fast = [fast_press(p, SETTINGS) for p in presses]
    assert all(f.two_segment for f in fast)
    batch = simulate_presses([*presses, *fast], -40.0, model, out_dt_s=1e-3)
    x0, _ = sample_presses([*presses, *fast], batch.t_s)
    assert np.max(np.abs(batch.x0_m - x0)) < 1e-9


CASES = [  # (down speed m/s, acceleration m/s², depth m, vacuum kPa): the study's range
    (0.01, 0.1, 0.03, -40.0), (0.01, 1.0, 0.04, -80.0), (0.015, 0.5, 0.03, -40.0),
    (0.02, 0.1, 0.04, -80.0), (0.02, 0.5, 0.04, -20.0), (0.025, 1.0, 0.03, -60.0),
]


@pytest.mark.slow
def test_fast_press_meets_the_key_like_the_specified_press() -> None:
    """Contact speed and the key's response of the fast press match within the world's noise.

    Noise here: MIDI velocity is an integer. The world's finger stiffness drifts by up to ±4 %
    between blocks, which moves the key speed at the trigger by several per cent and the
    deepest key travel by ~0.25 mm (one standard deviation, seed 3, 20 mm/s at -80 kPa); the
    fast press must stay well inside that: key speed within 2 %, key travel within 0.1 mm, and
    the fingertip's speed at contact within 2 % or the speed noise of two 120 Hz mocap frames
    (√2 · 3 µm · 120 Hz ≈ 0.5 mm/s).
    """
    world = World.default(seed=3)
    mocap = world.config.mocap
    tip_noise_mps = math.sqrt(2.0) * mocap.noise_m * mocap.rate_hz
    spec = [Press(0.05, depth, v, v, a) for v, a, depth, _ in CASES]
    fast = [fast_press(p, SETTINGS) for p in spec]
    assert all(f.approach_m > 0.01 and f.retract_m > 0.04 for f in fast)
    vacuum = [c[3] for c in CASES]
    keys = [f"case{i}" for i in range(len(CASES))]
    blocks = [f"{p:g}" for p in vacuum]
    before = world.keystrokes(spec, vacuum, keys=keys, blocks=blocks)
    after = world.keystrokes(fast, vacuum, keys=keys, blocks=blocks)
    assert all(b.on_velocity is not None for b in before)  # they sound
    for p, f, b, k in zip(spec, fast, before, after, strict=True):
        assert contact_speed_mps(f) == pytest.approx(contact_speed_mps(p), rel=1e-12)
        assert press_duration_s(f) < 0.76 * press_duration_s(p)
        assert k.on_velocity == b.on_velocity
        assert k.key_speed_at_trigger_mps == pytest.approx(b.key_speed_at_trigger_mps, rel=0.02,
                                                           nan_ok=True)
        assert k.max_key_travel_m == pytest.approx(b.max_key_travel_m, abs=0.1e-3)
        # The fingertip itself meets the key at the same speed (its truth trace, at contact).
        assert _tip_speed_at_contact(k, p.distance_m) == pytest.approx(
            _tip_speed_at_contact(b, p.distance_m), rel=0.02, abs=tip_noise_mps)


def _tip_speed_at_contact(stroke: object, distance_m: float) -> float:
    t = np.asarray(stroke.truth_t_s)  # type: ignore[attr-defined]
    gap = np.asarray(stroke.truth_x1_m) - np.asarray(stroke.truth_x2_m)  # type: ignore[attr-defined]
    k = int(np.argmax(gap >= distance_m))
    f = (distance_m - gap[k - 1]) / (gap[k] - gap[k - 1])
    v1 = np.gradient(np.asarray(stroke.truth_x1_m), t)  # type: ignore[attr-defined]
    return float(v1[k - 1] + f * (v1[k] - v1[k - 1]))


def test_settling_is_what_keeps_the_finger_state() -> None:
    """With no settling the arm is still exact, but the finger sways from the stop (why the
    default keeps 1.5 s of the spec's motion before contact)."""
    world = World.default(seed=3)
    press = Press(0.05, 0.03, 0.02, 0.02, 1.0)
    eager = fast_press(press, ApproachSettings(settle_s=0.0))
    patient = fast_press(press, SETTINGS)
    strokes = world.keystrokes([press, eager, patient], -60.0, keys=["k"] * 3, blocks=["b"] * 3)
    tips = [_tip_speed_at_contact(s, press.distance_m) for s in strokes]
    assert contact_speed_mps(eager) == pytest.approx(contact_speed_mps(press))
    assert abs(tips[1] / tips[0] - 1) > 5 * abs(tips[2] / tips[0] - 1)
    assert math.isfinite(tips[2]) and abs(tips[2] / tips[0] - 1) < 0.02


@pytest.mark.parametrize("world", [World.default(), World.linear()], ids=["default", "linear"])
def test_fast_and_plain_presses_are_the_same_alone_and_side_by_side(world: World) -> None:
    """A batch with two-segment presses uses another arm formula; no keystroke may notice."""
    plain = [Press(0.05, 0.03, v, v, a) for v, a in ((0.01, 0.1), (0.03, 1.0), (0.06, 0.5))]
    fast = [fast_press(p, SETTINGS) for p in plain[:2]]
    batch = world.simulate([*plain, *fast] * 7, -40.0)
    for j, press in enumerate([*plain, *fast]):
        alone = world.simulate([press], -40.0)
        T = alone.t_s.size
        for name in ("x0_m", "x1_m", "x2_m", "v2_mps", "contact_force_n"):
            assert np.array_equal(getattr(batch, name)[j, :T], getattr(alone, name)[0]), name
            assert np.array_equal(getattr(batch, name)[j + 5 * 6, :T], getattr(alone, name)[0])
