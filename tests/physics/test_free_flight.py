"""A press started in flight (`physics.free_flight`) gives the same keystroke as one simulated
from rest, and it starts only where its fingertip cannot yet have reached the key."""

from __future__ import annotations

import numpy as np
import pytest

from pianobot.physics.model import KeystrokeModel
from pianobot.physics.simulate import FlightStarts, flight_starts, simulate_presses
from pianobot.physics.trajectory import Press

OUT_DT_S, STEP_S = 1e-3, 2e-4


def _presses() -> list[Press]:
    return [Press(0.05, depth, v, v, a, 0.05)
            for a in (0.1, 1.0) for v in (0.01, 0.03, 0.08) for depth in (0.01, 0.03)]


STUDY = KeystrokeModel.study()
MODELS = {
    "study ramp": STUDY,
    "trapezoid": STUDY.with_effect("arm_acceleration"),
    "trapezoid, key-side effects": STUDY.with_effect("arm_acceleration").with_effect("contact")
    .with_effect("keybed").with_effect("key_friction").with_effect("letoff"),
    "arm delay": STUDY.with_effect("arm_acceleration").with_effect("arm_lag", form="delay", arm_lag_s=0.03),
    "power-law finger, drift": STUDY.with_effect("finger_stiffening", form="power")
    .with_effect("stiffness_drift"),
}


def _both(model: KeystrokeModel, presses: list[Press], vacuum: np.ndarray, keys: list[str]
          ) -> tuple[FlightStarts, object, object]:
    start = flight_starts(presses, vacuum, model, out_dt_s=OUT_DT_S, step_s=STEP_S, block_keys=keys)
    full = simulate_presses(presses, vacuum, model, out_dt_s=OUT_DT_S, duration_s=8.0, step_s=STEP_S,
                            block_keys=keys)
    late = simulate_presses(presses, vacuum, model, out_dt_s=OUT_DT_S, duration_s=8.0 - start.start_s.max(),
                            step_s=STEP_S, block_keys=keys, start=start)
    return start, full, late


@pytest.mark.parametrize("name", list(MODELS))
def test_a_press_started_in_flight_is_the_press_simulated_from_rest(name: str) -> None:
    presses = _presses()
    vacuum = np.resize([-60.0, -10.0, -30.0], len(presses))
    keys = [f"block{i % 2}" for i in range(len(presses))]
    start, full, late = _both(MODELS[name], presses, vacuum, keys)
    skipped = np.rint(start.start_s / OUT_DT_S).astype(int)
    assert skipped.min() > 0 and skipped.max() > 4000  # 5 cm at 0.01 m/s: about 5 s skipped
    n = late.t_s.size  # type: ignore[attr-defined]
    for j, k in enumerate(skipped):
        for signal in ("x1_m", "x2_m", "contact_force_n", "v2_mps"):
            want = getattr(full, signal)[j, k : k + n]
            got = getattr(late, signal)[j, : want.size]
            scale = max(float(np.max(np.abs(getattr(full, signal)[j]))), 1e-12)
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-11 * scale, err_msg=f"{signal}, press {j}")


def test_the_start_is_before_the_fingertip_can_reach_the_key_for_any_finger() -> None:
    """Light and heavy fingertips, soft and stiff arms, barely damped ones: wherever the
    simulation starts, the fingertip simulated from rest has not yet touched the key."""
    rng = np.random.default_rng(11)
    presses = [Press(float(rng.uniform(0.002, 0.06)), 0.01, float(rng.uniform(0.005, 0.2)), 0.05,
                     float(rng.choice([0.05, 0.3, 3.0])), 0.0) for _ in range(24)]
    for trial in range(6):
        msd = STUDY.msd.replace(m1_kg=STUDY.msd.m1_kg * rng.uniform(0.3, 4.0),
                                c1_nspm=STUDY.msd.c1_nspm * rng.uniform(0.05, 3.0))
        model = STUDY.replace(msd=msd)
        if trial % 2:
            model = model.with_effect("arm_acceleration")
        start = flight_starts(presses, -40.0, model, out_dt_s=OUT_DT_S, step_s=STEP_S)
        full = simulate_presses(presses, -40.0, model, out_dt_s=OUT_DT_S, step_s=STEP_S)
        gap = full.x1_m - full.x2_m - np.array([p.distance_m for p in presses])[:, None]
        touched = np.where((gap >= 0).any(axis=1), np.argmax(gap >= 0, axis=1) * OUT_DT_S, np.inf)
        assert np.all(start.start_s < touched), (trial, start.start_s, touched)
        assert np.any(start.start_s > 0)


def test_models_and_presses_that_cannot_start_in_flight_start_at_rest() -> None:
    presses = _presses()
    trapezoid = STUDY.with_effect("arm_acceleration")
    for model in (trapezoid.with_effect("arm_lag", form="first_order", arm_lag_s=0.02),
                  trapezoid.with_effect("finger_hysteresis")):
        start = flight_starts(presses, -40.0, model, out_dt_s=OUT_DT_S, step_s=STEP_S)
        assert not start.start_s.any() and not start.state.any()
        borrowed = flight_starts(presses, -40.0, trapezoid, out_dt_s=OUT_DT_S, step_s=STEP_S)
        with pytest.raises(ValueError, match="at rest only"):
            simulate_presses(presses, -40.0, model, out_dt_s=OUT_DT_S, step_s=STEP_S, start=borrowed)
    two_segment = [Press(0.05, 0.02, 0.02, 0.02, 0.5, 0.0, approach_m=0.03, retract_m=0.0,
                         travel_velocity_mps=0.25, travel_acceleration_mps2=1.0)]
    assert not flight_starts(two_segment, -40.0, trapezoid, out_dt_s=OUT_DT_S, step_s=STEP_S).start_s.any()
    # A fast retract comes after lift-off: such a press starts in flight, the same keystroke.
    retract_only = [Press(0.05, 0.02, 0.02, 0.02, 0.5, 0.0, approach_m=0.0, retract_m=0.03,
                          travel_velocity_mps=0.25, travel_acceleration_mps2=1.0)]
    late = flight_starts(retract_only, -40.0, trapezoid, out_dt_s=OUT_DT_S, step_s=STEP_S)
    k = int(round(late.start_s[0] / OUT_DT_S))
    assert k > 1000
    full = simulate_presses(retract_only, -40.0, trapezoid, out_dt_s=OUT_DT_S, step_s=STEP_S)
    part = simulate_presses(retract_only, -40.0, trapezoid, out_dt_s=OUT_DT_S, step_s=STEP_S,
                            duration_s=full.t_s[-1] - late.start_s[0], start=late)
    np.testing.assert_allclose(part.x0_m[0], full.x0_m[0, k:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(part.x2_m[0], full.x2_m[0, k:], rtol=0, atol=1e-12)
    start = flight_starts(presses, -40.0, trapezoid, out_dt_s=OUT_DT_S, step_s=STEP_S)
    with pytest.raises(ValueError, match="another out_dt_s or step_s"):
        simulate_presses(presses, -40.0, trapezoid, out_dt_s=OUT_DT_S, step_s=1e-4, start=start)
