"""Batch simulator: exact for the linear model, and each effect does what physics says."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pianobot.physics.effects import Effects
from pianobot.physics.linear import simulate_linear
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.msd import MSDParams
from pianobot.physics.piano import PianoParams, piano_events
from pianobot.physics.simulate import SimBatch, simulate_arm, simulate_presses
from pianobot.physics.trajectory import Press, sample_presses

STUDY = KeystrokeModel.study()


def test_linear_model_matches_the_exact_state_space_solution() -> None:
    presses = [Press(0.0, 0.03, 0.04, 0.04, 1.0, 0.2), Press(0.0, 0.02, 0.08, 0.02, 1.0, 0.0)]
    batch = simulate_presses(presses, [-60.0, -20.0], STUDY, duration_s=1.5)
    x0, _ = sample_presses(presses, batch.t_s, profile="ramp")
    for j, p in enumerate((-60.0, -20.0)):
        x1, x2 = simulate_linear(MSDParams().at(p), batch.t_s, x0[j])
        assert np.max(np.abs(batch.x0_m[j] - x0[j])) < 1e-12
        assert np.max(np.abs(batch.x2_m[j] - x2)) < 1e-3 * np.max(np.abs(x2))
        assert np.max(np.abs(batch.x1_m[j] - x1)) < 1e-3 * np.max(np.abs(x1))


def test_error_shrinks_with_the_step() -> None:
    press = [Press(0.0, 0.03, 0.06, 0.06, 1.0, 0.0)]
    ref = simulate_presses(press, -60, STUDY, duration_s=1.2, step_s=1e-5)
    err = [
        np.max(np.abs(simulate_presses(press, -60, STUDY, duration_s=1.2, step_s=h).x2_m - ref.x2_m))
        for h in (2e-4, 1e-4)
    ]
    assert err[1] < err[0] < 1e-6


def test_step_limit_and_shapes() -> None:
    with pytest.raises(ValueError, match="step_s"):
        simulate_presses([Press(0.0, 0.03, 0.04, 0.04, 1.0)], -60, STUDY, step_s=5e-4)
    b = simulate_presses([Press(0.05, 0.03, 0.04, 0.04, 1.0)] * 3, -60, STUDY, out_dt_s=2e-3)
    assert isinstance(b, SimBatch)
    assert b.x2_m.shape == (3, b.t_s.size) and b.contact_force_n.shape == b.x2_m.shape
    assert np.allclose(np.diff(b.t_s), 2e-3)
    df = b.to_pandas()
    assert len(df) == 3 * b.t_s.size and {"keystroke", "t_s", "x2_m"} <= set(df.columns)


def test_simulate_arm_reproduces_the_press_simulation() -> None:
    model = STUDY.with_effect("contact").with_effect("keybed").with_effect("arm_acceleration")
    presses = [Press(0.01, 0.03, 0.05, 0.05, 1.0, 0.1)] * 2
    ref = simulate_presses(presses, -60, model, duration_s=1.0)
    t = np.arange(0.0, 1.0 + 1e-9, 1e-4)
    x0, _ = sample_presses(presses, t, profile="trapezoid")
    got = simulate_arm(t, x0, -60, model, distance_m=0.01)
    assert np.allclose(got.t_s, ref.t_s)
    assert np.max(np.abs(got.x2_m - ref.x2_m)) < 5e-6


def test_a_key_left_down_starts_there_held_by_friction_or_springs_back_without_it() -> None:
    """`key_start_m`: the key starts that far below rest with its spring loaded, and the
    fingertip that much farther above it; 0 is the key at rest, bit for bit as before."""
    t = np.arange(0.0, 1.0 + 1e-9, 1e-4)
    x0, _ = sample_presses([Press(0.0, 0.006, 0.02, 0.02, 1.0, 0.2)], t, profile="trapezoid")
    held = STUDY.with_effect("contact").with_effect("key_friction", form="stribeck", friction_n=0.1,
                                                    static_friction_n=0.2)  # k2 * 0.4 mm = 0.12 N < 0.2 N
    start = 4e-4
    at_rest = simulate_arm(t, x0, -40, held)
    assert np.array_equal(simulate_arm(t, x0, -40, held, key_start_m=0.0).x2_m, at_rest.x2_m)
    left = simulate_arm(t, x0, -40, held, key_start_m=start)
    touch = int(np.argmax(at_rest.x2_m[0] > 1e-6))  # the key at rest moves at first touch
    assert np.all(left.x2_m[0, : touch + 1] == start)  # held: it waits for the finger
    assert left.x2_m[0].max() > start + 1e-4  # and moves once pushed past the breakaway
    # The fingertip starts 0.4 mm farther above this key: it touches later than at rest.
    assert int(np.argmax(left.x2_m[0] > start + 1e-6)) > touch
    free = simulate_arm(t, x0, -40, STUDY.with_effect("contact"), key_start_m=start)
    assert free.x2_m[0, 50] < 0.5 * start  # without friction its spring sends it back up at once


def test_simulate_arm_rejects_gaps() -> None:
    t = np.linspace(0.0, 1.0, 11)
    x = np.zeros(11)
    x[3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        simulate_arm(t, x, -60, STUDY)


def test_keybed_caps_key_travel() -> None:
    press = [Press(0.0, 0.04, 0.08, 0.08, 1.0, 0.2)]
    model = STUDY.with_effect("contact")
    free = simulate_presses(press, -80, model)
    assert free.x2_m.max() > 0.008
    for form in ("linear", "hunt_crossley"):
        capped = simulate_presses(press, -80, model.with_effect("keybed", form=form, bed_depth_m=0.006))
        assert 0.006 < capped.x2_m.max() < 0.0068


def test_preload_makes_slow_shallow_presses_silent() -> None:
    press = [Press(0.01, 0.025, 0.01, 0.01, 1.0, 0.0)]
    piano = PianoParams(jitter_s=0.0)
    loose = simulate_presses(press, -60, STUDY.with_effect("contact"))
    held = simulate_presses(press, -60, STUDY.with_effect("contact").with_effect("key_preload"))
    assert piano_events(loose.t_s, loose.x2_m, piano)[0], "sounds without preload"
    assert piano_events(held.t_s, held.x2_m, piano) == [[]]
    assert held.x2_m.min() >= 0.0  # the rest stop holds the key


def test_a_smooth_rest_stop_lets_go_over_its_width_and_is_the_rigid_one_when_narrow() -> None:
    """key_preload `smooth`: the stop's push fades over the width (a net −P·tanh(x/w)), so the
    key starts to move below the preload and further down it feels the full preload; a narrow
    width is the rigid stop."""
    press = [Press(0.005, 0.012, 0.02, 0.02, 1.0, 0.2)]
    touch = STUDY.with_effect("contact")
    rigid = simulate_presses(press, -40, touch.with_effect("key_preload", preload_n=0.4), step_s=2e-5)
    narrow = simulate_presses(press, -40, touch.with_effect("key_preload", form="smooth", preload_n=0.4,
                                                            preload_width_m=2e-5), step_s=2e-5)
    felt = simulate_presses(press, -40, touch.with_effect("key_preload", form="smooth", preload_n=0.4,
                                                          preload_width_m=5e-4), step_s=2e-5)
    assert np.max(np.abs(narrow.x2_m - rigid.x2_m)) < 0.05 * rigid.x2_m.max()
    moved = [float(b.t_s[np.argmax(b.x2_m[0] > 1e-4)]) for b in (rigid, felt)]
    assert moved[1] < moved[0] - 0.05  # the felt gives before the preload is reached
    # Past a few widths the felt key carries the whole preload: it stops about as deep.
    assert abs(felt.x2_m.max() - rigid.x2_m.max()) < 0.1 * rigid.x2_m.max()


def test_a_cohesive_skin_pulls_as_the_law_says_and_lets_go_at_its_range() -> None:
    """adhesion `cohesive`: once the fingertip has left the key, the skin pulls with
    (27/4)·F·s·(1 − s)² of the separation s (in ranges): peak F at a third of the range, nothing
    beyond it. The contact force at each sample is that law at the sample's positions."""
    press = [Press(0.0, 0.03, 0.05, 0.7, 5.0, 0.3)]
    peak, reach = 0.1, 1e-3
    skin = STUDY.with_effect("arm_acceleration").with_effect("contact").with_effect(
        "adhesion", form="cohesive", pull_off_force_n=peak, adhesion_range_m=reach)
    b = simulate_presses(press, -60, skin, step_s=2e-5)
    gap = b.x2_m[0] - b.x1_m[0]  # the fingertip starts on the key (distance 0)
    s = np.clip(gap / reach, 0.0, 1.0)
    law = -6.75 * peak * s * (1.0 - s) ** 2
    parted = gap > 0.0
    assert parted.sum() > 20 and np.any(gap > 1.5 * reach)
    assert np.max(np.abs(b.contact_force_n[0][parted] - law[parted])) < 1e-9
    assert -peak - 1e-9 <= b.contact_force_n.min() < -0.9 * peak
    # The pull draws the key up after the retracting finger: above a key no skin holds.
    free = simulate_presses(press, -60, STUDY.with_effect("arm_acceleration").with_effect("contact"), step_s=2e-5)
    assert np.min(b.x2_m - free.x2_m) < -5e-5

def test_contact_lets_the_key_lag_a_fast_retracting_finger() -> None:
    press = [Press(0.0, 0.03, 0.05, 0.7, 5.0, 0.3)]
    glued = simulate_presses(press, -60, STUDY.with_effect("arm_acceleration"))
    free = simulate_presses(press, -60, STUDY.with_effect("arm_acceleration").with_effect("contact"))
    assert glued.contact_force_n.min() < -0.05  # the bilateral spring pulls the key up
    assert free.contact_force_n.min() >= 0.0  # a finger only pushes
    gap = free.x1_m[0] - free.x2_m[0]  # distance 0: negative gap = separated
    assert gap.min() < -1e-3
    assert np.max(free.x2_m[0] - glued.x2_m[0]) > 5e-4  # the key is left behind


def test_power_stiffening_is_the_cubic_at_exponent_two_and_sharper_above() -> None:
    """k1·δ·(1 + (βδ)^q): q = 2 is the cubic form exactly; a larger q adds less below δ = 1/β
    and more above it, so a press that compresses the finger past 1/β stops the key deeper."""
    press = [Press(0.0, 0.03, 0.08, 0.08, 1.0, 0.2)]
    model = STUDY.with_effect("contact")
    cubic = simulate_presses(press, -60, model.with_effect("finger_stiffening", form="cubic", stiffening_per_m=250.0))
    power = model.with_effect("finger_stiffening", form="power", stiffening_per_m=250.0)
    same = simulate_presses(press, -60, power.with_effect("finger_stiffening", stiffening_exponent=2.0))
    np.testing.assert_allclose(same.x2_m, cubic.x2_m, rtol=0, atol=1e-12)
    sharp = simulate_presses(press, -60, power.with_effect("finger_stiffening", stiffening_exponent=4.0))
    linear = simulate_presses(press, -60, model)
    compression = linear.x1_m[0] - linear.x2_m[0]
    assert compression.max() > 1.0 / 250.0  # the press reaches past 1/β
    assert linear.x2_m.max() < cubic.x2_m.max() < sharp.x2_m.max()


def test_friction_shortens_ringing() -> None:
    press = [Press(0.0, 0.02, 0.05, 0.2, 2.0, 0.2)]
    model = STUDY.with_effect("arm_acceleration")
    plain = simulate_presses(press, -60, model, duration_s=2.0)
    rubbed = simulate_presses(press, -60, model.with_effect("key_friction"), duration_s=2.0)
    tail = plain.t_s > 1.0

    def ringing(b: SimBatch) -> float:
        return float(np.sum(np.abs(np.diff(b.x2_m[0, tail]))))

    assert ringing(rubbed) < 0.5 * ringing(plain)
    assert ringing(plain) > 1e-4


@pytest.mark.parametrize("acc", [0.1, 0.3])
def test_arm_acceleration_caps_contact_speed(acc: float) -> None:
    distance = 0.01
    press = [Press(distance, 0.03, 0.08, 0.08, acc, 0.0)]
    cap = math.sqrt(2 * acc * distance)
    speeds = {}
    for name, model in (("ramp", STUDY), ("trapezoid", STUDY.with_effect("arm_acceleration"))):
        b = simulate_presses(press, -60, model, out_dt_s=1e-4)
        k = int(np.argmax(b.x1_m[0] - b.x2_m[0] >= distance))
        speeds[name] = (b.x0_m[0, k + 1] - b.x0_m[0, k - 1]) / 2e-4  # arm speed at touch
    assert speeds["ramp"] > 0.07
    assert speeds["trapezoid"] <= 1.05 * cap


def test_arm_lag_delays_the_arm_and_drift_follows_blocks() -> None:
    press = [Press(0.05, 0.03, 0.05, 0.05, 1.0)]
    prompt = simulate_presses(press, -60, STUDY)
    for form in ("first_order", "delay"):
        lagged = simulate_presses(press, -60, STUDY.with_effect("arm_lag", form=form, arm_lag_s=0.02))
        i = np.searchsorted(prompt.t_s, 0.5)
        assert lagged.x0_m[0, i] < prompt.x0_m[0, i] - 5e-4
    drift = STUDY.with_effect("stiffness_drift", drift_fraction=0.2)
    b = simulate_presses(press * 3, -60, drift, block_keys=["a", "b", "a"])
    assert np.array_equal(b.x2_m[0], b.x2_m[2])
    assert not np.allclose(b.x2_m[0], b.x2_m[1])


def test_all_effects_together_stay_finite_and_bounded() -> None:
    presses = [Press(0.05, d, v, v, a, 0.1) for d in (0.02, 0.04) for v in (0.01, 0.08) for a in (0.1, 2.0)]
    for effects in (Effects.all(), Effects.default_world()):
        b = simulate_presses(presses, -80, KeystrokeModel(effects=effects))
        assert np.all(np.isfinite(b.x2_m))
        assert b.x2_m.max() < 0.012 and b.x2_m.min() >= 0.0
        assert np.all(np.abs(b.x2_m[:, -1]) < 1e-4)  # back at rest


def test_adhesion_pulls_up_to_the_pull_off_force_and_letoff_resists_descent() -> None:
    press = [Press(0.0, 0.03, 0.05, 0.7, 5.0, 0.3)]
    sticky = STUDY.with_effect("arm_acceleration").with_effect("contact").with_effect("adhesion", pull_off_force_n=0.1)
    b = simulate_presses(press, -60, sticky)
    assert -0.1 - 1e-9 <= b.contact_force_n.min() < -0.05
    slow = [Press(0.0, 0.04, 0.05, 0.05, 1.0, 0.2)]
    base = STUDY.with_effect("contact")
    bumped = base.with_effect("letoff", letoff_force_n=0.6, letoff_depth_m=0.004)
    a, c = simulate_presses(slow, -80, base), simulate_presses(slow, -80, bumped)

    def time_to(b: SimBatch, depth: float) -> float:
        return float(b.t_s[np.argmax(b.x2_m[0] >= depth)])

    assert time_to(c, 0.005) > time_to(a, 0.005) + 0.01
