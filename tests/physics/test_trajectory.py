"""UR moveL profiles: phase times, areas, peaks, continuity, contact speed."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pianobot.physics.trajectory import (
    MoveProfile,
    Press,
    contact_speed_mps,
    move_profile,
    press_duration_s,
    press_timing,
    sample_presses,
)

distances = st.floats(1e-4, 0.1)
speeds = st.floats(1e-3, 0.7)
accels = st.floats(0.05, 2.0)


@settings(deadline=None)  # no wall-clock limits: the machine is shared
@given(distances, speeds, accels)
def test_profile_phases_add_up_and_cover_the_distance(d: float, v: float, a: float) -> None:
    prof = move_profile(d, v, a)
    assert prof.duration_s == pytest.approx(2 * prof.t_accel_s + prof.t_cruise_s)
    # Area under the speed profile: two ramps (½·peak·t_accel each) plus the cruise.
    area = prof.peak_velocity_mps * (prof.t_accel_s + prof.t_cruise_s)
    assert area == pytest.approx(d, rel=1e-9)
    assert prof.peak_velocity_mps <= v * (1 + 1e-12)
    assert prof.peak_velocity_mps == pytest.approx(a * prof.t_accel_s)


@settings(deadline=None)  # no wall-clock limits: the machine is shared
@given(distances, speeds, accels)
def test_triangle_when_too_short_to_cruise(d: float, v: float, a: float) -> None:
    prof = move_profile(d, v, a)
    if d < v * v / a:
        assert prof.t_cruise_s == 0.0
        assert prof.peak_velocity_mps == pytest.approx(math.sqrt(a * d))
        assert prof.duration_s == pytest.approx(2 * math.sqrt(d / a))
    else:
        assert prof.peak_velocity_mps == v
        assert prof.t_accel_s == pytest.approx(v / a)
        assert prof.duration_s == pytest.approx(d / v + v / a)


def test_known_trapezoid_numbers() -> None:
    prof = move_profile(0.08, 0.04, 0.1)
    assert prof.t_accel_s == pytest.approx(0.4)
    assert prof.t_cruise_s == pytest.approx(1.6)
    assert prof.duration_s == pytest.approx(2.4)
    tri = move_profile(0.01, 0.5, 1.0)  # v²/a = 0.25 m > 0.01 m
    assert tri.peak_velocity_mps == pytest.approx(0.1)
    assert tri.duration_s == pytest.approx(0.2)


def test_zero_distance_and_ramp() -> None:
    zero = move_profile(0.0, 0.05, 1.0)
    assert zero.duration_s == 0.0 and zero.peak_velocity_mps == 0.0
    x, v = zero.sample(np.array([-1.0, 0.0, 1.0]))
    assert np.all(x == 0.0) and np.all(v == 0.0)
    ramp = move_profile(0.03, 0.04, math.inf)
    assert ramp.t_accel_s == 0.0 and ramp.duration_s == pytest.approx(0.75)
    x, v = ramp.sample(np.array([0.0, 0.25, 0.5, 0.75, 1.0]))
    np.testing.assert_allclose(x, [0.0, 0.01, 0.02, 0.03, 0.03])
    np.testing.assert_allclose(v, [0.04, 0.04, 0.04, 0.0, 0.0])


@pytest.mark.parametrize(
    ("d", "v", "a"), [(-0.01, 0.1, 1.0), (0.01, 0.0, 1.0), (0.01, 0.1, 0.0), (0.01, -1, 1)]
)
def test_bad_moves_are_refused(d: float, v: float, a: float) -> None:
    with pytest.raises(ValueError, match="got"):
        move_profile(d, v, a)


presses = st.builds(
    Press,
    distance_m=st.floats(0.0, 0.05),
    depth_m=st.floats(0.001, 0.04),
    down_velocity_mps=st.floats(0.005, 0.5),
    up_velocity_mps=st.floats(0.005, 0.7),
    acceleration_mps2=accels,
    hold_s=st.floats(0.0, 0.5),
)


@settings(max_examples=40, deadline=None)
@given(presses)
def test_sampled_press_is_continuous_and_consistent(press: Press) -> None:
    timing = press_timing(press)
    dt = 1e-4
    phase_times = [timing.t_down_end_s, timing.t_hold_end_s, timing.t_end_s]
    t = np.union1d(np.arange(-0.05, timing.t_end_s + 0.05, dt), phase_times)
    x, v = sample_presses([press], t)
    x, v = x[0], v[0]
    travel = press.distance_m + press.depth_m
    # At rest before the start and after the end, never beyond the travel, never above start.
    assert np.all(x[t < 0] == 0.0) and np.all(v[t < 0] == 0.0)
    assert np.all(np.abs(x[t >= timing.t_end_s]) < 1e-12)
    assert x.max() == pytest.approx(travel, rel=1e-9)
    assert x.min() >= -1e-12 and x.max() <= travel * (1 + 1e-12)
    # Continuity: no jump bigger than the fastest speed allows over one step.
    v_max = max(timing.down.peak_velocity_mps, timing.up.peak_velocity_mps)
    assert np.max(np.abs(np.diff(x))) <= v_max * dt * (1 + 1e-6) + 1e-15
    # The speed is the derivative of the position: its integral reproduces x.
    x_int = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    assert np.max(np.abs(x_int - x)) < 2 * v_max * dt + 1e-9
    # Down then up: speeds have the right signs in each phase.
    assert np.all(v[t < timing.t_down_end_s] >= 0.0)
    assert np.all(v[t > timing.t_hold_end_s] <= 0.0)
    assert np.all(x[(t >= timing.t_down_end_s) & (t <= timing.t_hold_end_s)] == travel)


def test_press_timing_and_duration() -> None:
    press = Press(0.05, 0.03, 0.04, 0.08, 0.1, hold_s=0.2)
    timing = press_timing(press)
    assert timing.t_down_end_s == pytest.approx(2.4)
    assert timing.t_hold_end_s == pytest.approx(2.6)
    up = move_profile(0.08, 0.08, 0.1)  # 0.8 s accel + 0.2 s cruise + 0.8 s brake
    assert timing.t_end_s == pytest.approx(2.6 + up.duration_s)
    assert press_duration_s(press) == pytest.approx(timing.t_end_s)
    assert press_duration_s(press, "ramp") == pytest.approx(0.08 / 0.04 + 0.2 + 0.08 / 0.08)


def test_vectorised_over_presses_equals_one_by_one() -> None:
    batch = [
        Press(0.05, 0.03, 0.04, 0.04, 0.1),
        Press(0.0, 0.02, 0.3, 0.5, 2.0, hold_s=0.1),
        Press(0.01, 0.035, 0.08, 0.7, 0.5, hold_s=0.3),
    ]
    t = np.linspace(-0.1, 3.0, 777)
    x, v = sample_presses(batch, t)
    assert x.shape == v.shape == (3, 777)
    for i, press in enumerate(batch):
        xi, vi = sample_presses([press], t)
        np.testing.assert_array_equal(x[i], xi[0])
        np.testing.assert_array_equal(v[i], vi[0])
    empty_x, empty_v = sample_presses([], t)
    assert empty_x.shape == (0, 777) and empty_v.shape == (0, 777)


def test_ramp_profile_is_constant_speed() -> None:
    press = Press(0.0, 0.03, 0.04, 0.04, 0.1, hold_s=0.5)
    t = np.arange(0.0, 2.0, 1e-3)
    x, v = sample_presses([press], t, profile="ramp")
    down = t < 0.75
    np.testing.assert_allclose(x[0, down], 0.04 * t[down], atol=1e-15)
    np.testing.assert_allclose(v[0, down], 0.04)
    np.testing.assert_allclose(v[0, (t > 1.25) & (t < 2.0)], -0.04)
    with pytest.raises(ValueError, match="profile"):
        sample_presses([press], t, profile="sine")  # type: ignore[arg-type]


@settings(max_examples=60, deadline=None)
@given(presses)
def test_contact_speed_capped_by_acceleration(press: Press) -> None:
    a, s, depth = press.acceleration_mps2, press.distance_m, press.depth_m
    expected = min(press.down_velocity_mps, math.sqrt(2 * a * s), math.sqrt(2 * a * depth))
    speed = contact_speed_mps(press)
    assert speed == pytest.approx(expected, rel=1e-9, abs=1e-15)
    assert speed <= math.sqrt(2 * a * depth) * (1 + 1e-12)
    # Same number read off the sampled profile at the moment the arm reaches the key.
    down = press_timing(press).down
    t_contact = down.time_at_m(s)
    _, v = down.sample(np.array([t_contact]))
    if 0.0 < t_contact < down.duration_s:
        assert float(v[0]) == pytest.approx(expected, rel=1e-6, abs=1e-12)
    assert contact_speed_mps(press, "ramp") == press.down_velocity_mps


def test_low_acceleration_caps_contact_speed() -> None:
    # At 0.1 m/s² the arm cannot brake from 0.08 m/s within 20 mm of depth: contact is slower.
    press = Press(0.05, 0.02, 0.08, 0.08, 0.1)
    assert contact_speed_mps(press) == pytest.approx(math.sqrt(2 * 0.1 * 0.02))
    assert contact_speed_mps(press) < 0.08


@settings(deadline=None)  # no wall-clock limits: the machine is shared
@given(distances, speeds, accels, st.floats(0.0, 1.0))
def test_time_at_distance_inverts_the_profile(d: float, v: float, a: float, frac: float) -> None:
    prof: MoveProfile = move_profile(d, v, a)
    t = prof.time_at_m(frac * d)
    x, _ = prof.sample(np.array([t]))
    assert float(x[0]) == pytest.approx(frac * d, rel=1e-7, abs=1e-12)


def test_bad_press_is_refused() -> None:
    with pytest.raises(ValueError, match="depth"):
        press_timing(Press(0.05, -0.01, 0.04, 0.04, 1.0))
    with pytest.raises(ValueError, match="Hold"):
        press_timing(Press(0.05, 0.01, 0.04, 0.04, 1.0, hold_s=-1.0))
