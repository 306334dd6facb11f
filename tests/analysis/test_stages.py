"""The five keystroke stages and features on a simulated keystroke (with dropped frames)."""

from __future__ import annotations

import numpy as np

from pianobot.analysis.greybox.features import keystroke_features
from pianobot.analysis.greybox.stages import STAGE_NAMES, find_stages
from pianobot.physics.linear import simulate_linear
from pianobot.physics.msd import MSDParams
from pianobot.physics.trajectory import Press, sample_presses


def _stroke() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    t = np.arange(-0.1, 1.0, 1 / 120)
    x0, _ = sample_presses([Press(0.0, 0.008, 0.03, 0.03, 1.0, 0.2)], t)
    x1, x2 = simulate_linear(MSDParams().at(-40.0), t, x0[0])
    return t, x0[0], x1, x2


def test_stages_are_ordered_and_labelled() -> None:
    t, x0, x1, x2 = _stroke()
    x2 = x2.copy()
    x2[40:43] = np.nan  # dropped frames
    st = find_stages(t, x2, x0_m=x0, x1_m=x1)
    edges = st.boundaries_s
    assert np.all(np.isfinite(edges)) and np.all(np.diff(edges) >= 0)
    assert abs(st.t_motion_s) < 0.02
    labels = st.label(t)
    # the finger starts on the key (distance 0): no approach; the key stages are all present
    assert {"press", "bottom", "release"} <= set(labels.tolist()) <= set(STAGE_NAMES) | {""}


def test_features_key_speed_and_travel() -> None:
    t, x0, x1, x2 = _stroke()
    travel = float(np.max(x2))
    f = keystroke_features(t, x2, trigger_depth_m=0.5 * travel, x0_m=x0, x1_m=x1)
    assert f.max_key_travel_m == np.float64(travel) or abs(f.max_key_travel_m - travel) < 1e-9
    i = int(np.argmax(x2 >= 0.5 * travel))
    slope = (x2[i] - x2[i - 1]) * 120
    assert abs(f.key_speed_at_trigger_mps - slope) < 0.3 * abs(slope)
    assert 0 < f.time_to_trigger_s < 1.0 and f.contact_time_s > 0


def test_key_that_never_moves_has_only_approach() -> None:
    t = np.linspace(0, 1, 120)
    st = find_stages(t, np.zeros_like(t), x0_m=t * 0.01)
    assert np.isnan(st.t_key_move_s) and np.isfinite(st.t_motion_s)


def test_hovering_finger_traces_that_start_at_motion_start_find_the_contact() -> None:
    """Stored sweep traces begin at motion start (no rest samples before it): the rest level
    must come from their first instants, not from a fraction that reaches into the approach."""
    from pianobot.physics.world import World

    distance_m = 0.05
    ks = World.linear(0).keystroke(Press(distance_m, 0.03, 0.04, 0.04, 0.5, 0.2), -60.0, key="seg")
    t = ks.truth_t_s - ks.t0_s
    x0, x1, x2 = ks.truth_x0_m, ks.truth_x1_m, ks.truth_x2_m
    st = find_stages(t, x2, x0_m=x0, x1_m=x1, distance_m=distance_m)
    touch = float(t[np.argmax(x1 - x2 >= distance_m)])  # the fingertip reaches the key
    assert 0.0 <= st.t_motion_s < 0.1  # a 2 % travel threshold at 0.5 m/s² is crossed late
    assert np.isfinite(st.t_contact_s) and abs(st.t_contact_s - touch) < 0.02
    assert st.t_contact_s > 0.5  # 50 mm of approach at ≤ 0.04 m/s: not the first instant
