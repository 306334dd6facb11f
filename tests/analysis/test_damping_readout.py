"""Damping by logarithmic decrement and the piano readout, against known truth."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from _synthetic_runs import linear_keystrokes

from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.analysis.greybox.trajectories import keystroke_batch
from pianobot.analysis.identify.damping import damping_check, log_decrement, model_modes
from pianobot.analysis.identify.readout import fit_readout
from pianobot.physics.msd import MSDParams
from pianobot.physics.piano import PianoParams

TRUTH = MSDParams(k1_a_npm=70.0, k1_b_npm_per_kpa=1.4, c1_nspm=0.45, k2_npm=330.0, c2_nspm=0.33)


def test_log_decrement_of_a_damped_sine() -> None:
    t = np.arange(0.0, 1.5, 1 / 120)
    zeta, f = 0.06, 9.0
    wn = 2 * math.pi * f / math.sqrt(1 - zeta**2)
    x = 1e-3 * np.exp(-zeta * wn * t) * np.cos(2 * math.pi * f * t)
    x += np.random.default_rng(0).normal(0, 2e-6, t.size)
    f_hat, z_hat, n = log_decrement(t, x, min_amplitude_m=2e-5)
    assert n >= 8 and f_hat == pytest.approx(f, rel=0.03) and z_hat == pytest.approx(zeta, rel=0.1)


def test_free_ringing_matches_the_models_mode() -> None:
    trials, samples = linear_keystrokes(TRUTH, seed=1, levels_kpa=(-40.0,), duration_s=2.0)
    check = damping_check(keystroke_batch(samples, trials), TRUTH)
    assert check is not None and len(check.ringing) >= 2
    f_mode, z_mode = min(model_modes(TRUTH, -40.0), key=lambda m: abs(m[0] - check.frequency_hz))
    assert check.model_frequency_hz == f_mode and check.model_zeta == z_mode
    assert check.frequency_hz == pytest.approx(f_mode, rel=0.06)
    assert check.zeta == pytest.approx(z_mode, rel=0.15)


def test_no_ringing_gives_none() -> None:
    trials, samples = linear_keystrokes(TRUTH, seed=1, levels_kpa=(-40.0,))
    batch = keystroke_batch(samples.assign(x2_m=samples.x0_m * 0.5), trials)  # no oscillation
    assert damping_check(batch, TRUTH) is None


def test_readout_recovers_trigger_depth_and_curve() -> None:
    """Keys accelerating at known rates, velocities from a known power law of the speed between
    two sensors 2 mm apart with the lower one at 3 mm (a two-sensor digital action)."""
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 0.6, 1 / 240)
    speeds = rng.uniform(0.01, 0.06, 40)
    depth_true, gamma, s_full = 0.003, 1.6, 0.08
    # The key accelerates, at a rate of its own: only the right sensors explain the MIDI.
    accel = rng.uniform(0.05, 0.8, speeds.size)
    x2 = np.minimum(np.outer(speeds, t) + 0.5 * np.outer(accel, t**2), 0.009)

    def time_at(depth: float) -> np.ndarray:
        return (-speeds + np.sqrt(speeds**2 + 2 * accel * depth)) / accel

    transit = 0.002 / (time_at(depth_true) - time_at(depth_true - 0.002))
    velocity = np.clip(np.round(127 * (transit / s_full) ** gamma), 1, 127)
    ids = tuple(f"k{i}" for i in range(speeds.size))
    batch = KeystrokeBatch(ids, np.zeros(speeds.size), t, np.zeros_like(x2), np.full_like(x2, np.nan), x2)
    fit = fit_readout(batch, pd.DataFrame({"trial_id": ids, "on_velocity": velocity}))
    assert fit is not None and fit.n_trials == 40
    assert fit.trigger_depth_m == pytest.approx(depth_true, abs=0.0003)
    assert fit.curve_exponent == pytest.approx(gamma, rel=0.05)
    assert fit.full_scale_speed_mps == pytest.approx(s_full, rel=0.05)
    assert fit.linear_rmse_velocity > 2 * fit.rmse_velocity  # a straight line misreads the curve
    piano = fit.piano(PianoParams())
    assert piano.lower_sensor_m == fit.trigger_depth_m and piano.upper_sensor_m < fit.trigger_depth_m


def test_readout_needs_sounded_trials() -> None:
    trials, samples = linear_keystrokes(TRUTH, seed=1)
    assert fit_readout(keystroke_batch(samples, trials), trials) is None  # no on_velocity column
