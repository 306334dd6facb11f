"""The study's outcomes of the linear model, against the numbers of its MATLAB scripts."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pianobot.physics.msd import MSDParams
from pianobot.physics.study import (
    STUDY_OUTCOME_COLUMNS,
    STUDY_SCRIPT_PARAMS,
    study_arm_input,
    study_key_outcome,
    study_outcomes,
)

# (vacuum kPa, arm speed m/s) -> (on speed m/s, hold s), from the study's forward_control.m.
STUDY_EXAMPLES = [
    (-60.0, 0.04, 0.0121, 1.235),
    (-60.0, 0.08, 0.0428, 0.870),
    (0.0, 0.08, 0.0113, 0.629),
]


def test_study_outcomes_reproduce_the_study_numbers() -> None:
    vac = [v for v, *_ in STUDY_EXAMPLES]
    vel = [v for _, v, *_ in STUDY_EXAMPLES]
    df = study_outcomes(vac, vel)
    assert list(df.columns) == list(STUDY_OUTCOME_COLUMNS)
    for row, (_, _, on_speed, hold) in zip(df.itertuples(), STUDY_EXAMPLES, strict=True):
        assert row.on_speed_mps == pytest.approx(on_speed, rel=0.01)
        assert row.hold_s == pytest.approx(hold, rel=0.01)


def test_default_params_are_the_script_values() -> None:
    assert STUDY_SCRIPT_PARAMS.k2_npm == pytest.approx(150.6)
    assert STUDY_SCRIPT_PARAMS.at(-60).k0_npm == pytest.approx(146.81)
    default = study_outcomes(-60.0, 0.04)
    explicit = study_outcomes(-60.0, 0.04, params=STUDY_SCRIPT_PARAMS)
    pd.testing.assert_frame_equal(default, explicit)
    # The published key spring (300 N/m) is stiffer: the key moves less and triggers later.
    published = study_outcomes(-60.0, 0.04, params=MSDParams())
    assert published.hold_s[0] < default.hold_s[0]


def test_grid_broadcast_and_trends() -> None:
    vac = np.array([0.0, -40.0, -80.0])
    vel = np.array([0.03, 0.05, 0.08])
    df = study_outcomes(vac[:, None], vel[None, :])
    assert len(df) == 9
    np.testing.assert_array_equal(df.vacuum_kpa, np.repeat(vac, 3))
    np.testing.assert_array_equal(df.velocity_mps, np.tile(vel, 3))
    speeds = df.on_speed_mps.to_numpy().reshape(3, 3)
    # Faster arm -> faster key at every vacuum; at the fastest arm speed a stiffer finger
    # (more vacuum) gives a faster key (at slow speeds the trend is not monotone in the model).
    assert np.all(np.diff(speeds, axis=1) > 0)
    assert np.all(np.diff(speeds[:, -1]) > 0)
    # Paired arrays give one row per pair, in order, equal to the grid's entries.
    paired = study_outcomes(vac, vel)
    np.testing.assert_allclose(paired.on_speed_mps, np.diag(speeds), rtol=1e-12)


def test_unreachable_trigger_gives_nan_speed_and_zero_hold() -> None:
    # The key's static travel is about a third of the arm's: 30 mm of arm never reaches 25 mm.
    df = study_outcomes([-60.0, -60.0], [0.04, 0.04], threshold_m=0.025)
    assert df.on_speed_mps.isna().all()
    assert (df.hold_s == 0.0).all()


def test_bad_input_is_refused() -> None:
    with pytest.raises(ValueError, match="velocities"):
        study_outcomes(-60.0, 0.0)
    with pytest.raises(ValueError, match="threshold"):
        study_outcomes(-60.0, 0.04, threshold_m=0.0)
    with pytest.raises(ValueError, match="depth"):
        study_arm_input(-0.01, 0.04, 0.5)


def test_study_input_is_the_ramp() -> None:
    t, x0 = study_arm_input(0.03, 0.04, 0.5)
    assert t[-1] == pytest.approx(2 * 0.03 / 0.04 + 0.5)
    assert np.diff(t) == pytest.approx(1e-3)
    assert x0.max() == pytest.approx(0.03)
    assert x0[500] == pytest.approx(0.02)  # 0.5 s at 40 mm/s
    assert x0[-1] == pytest.approx(0.0, abs=1e-15)


def test_study_key_outcome_on_a_known_trace() -> None:
    dt = 1e-3
    t = np.arange(0.0, 1.0, dt)
    # Key goes down at 10 mm/s to 6 mm, holds 0.1 s, comes back at 20 mm/s.
    x2 = np.interp(t, [0.0, 0.6, 0.7, 1.0], [0.0, 0.006, 0.006, 0.0])
    on, hold = study_key_outcome(x2, 0.005, dt)
    assert float(on) == pytest.approx(0.01, rel=1e-9)  # 6 mm in 0.6 s
    # Beyond 5 mm from t = 0.5 s until 0.7 + 0.05 s: 250 samples (strictly beyond).
    assert float(hold) == pytest.approx(0.25, abs=2 * dt)
    batch_on, batch_hold = study_key_outcome(np.stack([x2, 0.5 * x2]), 0.005, dt)
    assert batch_on.shape == (2,)
    assert batch_on[0] == pytest.approx(0.01) and np.isnan(batch_on[1])
    assert batch_hold[1] == 0.0
