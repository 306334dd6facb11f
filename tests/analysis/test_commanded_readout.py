"""The commanded drive reads a model that differs only in its readout from key traces it has
already simulated: the same MIDI outcomes as simulating again, without the simulation."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from pianobot.analysis.greybox import commanded
from pianobot.analysis.greybox.commanded import KEPT_SIMULATIONS, Commanded
from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.physics.model import KeystrokeModel


def _batch(n: int = 12) -> KeystrokeBatch:
    rng = np.random.default_rng(3)
    return KeystrokeBatch(
        tuple(f"k{i}" for i in range(n)), np.full(n, -40.0), np.zeros(0), np.zeros((n, 0)), np.zeros((n, 0)),
        np.zeros((n, 0)), down_velocity_mps=rng.uniform(0.02, 0.1, n), up_velocity_mps=np.full(n, np.nan),
        acceleration_mps2=np.full(n, np.nan), depth_m=rng.uniform(0.004, 0.012, n), hold_s=np.full(n, 0.1),
        distance_m=np.full(n, 0.005))


def _outcomes(prediction: commanded.Prediction) -> np.ndarray:
    return np.stack([prediction.on_velocity, prediction.t_on_s, prediction.hold_s, prediction.margin_m])


def test_a_readout_change_is_read_from_the_kept_traces_with_the_same_outcomes(
        monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[int] = []
    simulate = commanded.simulate_presses
    monkeypatch.setattr(commanded, "simulate_presses", lambda *a, **k: calls.append(1) or simulate(*a, **k))
    study = KeystrokeModel.study()
    model = study.__class__(study.msd, study.effects.with_effect("arm_acceleration").with_effect("velocity_curve"),
                            study.piano)
    reread = model.__class__(model.msd, model.effects.with_effect("velocity_curve", curve_exponent=1.7),
                             model.piano.replace(lower_sensor_m=0.0035, full_scale_speed_mps=0.3))
    drive = {"acceleration_mps2": 0.8}
    kept = Commanded(_batch())
    first = kept.predict(model, drive)
    simulated = len(calls)
    assert simulated > 0
    again = kept.predict(reread, drive)
    assert len(calls) == simulated  # read again, not simulated
    fresh = Commanded(_batch()).predict(reread, drive)
    np.testing.assert_array_equal(_outcomes(again), _outcomes(fresh))  # bit for bit
    assert not np.array_equal(_outcomes(first), _outcomes(again), equal_nan=True)  # the readout did change

    # The model itself or the drive's acceleration is simulated again, and only so many are kept.
    stiffer = model.__class__(model.msd.replace(c1_nspm=model.msd.c1_nspm * 1.1), model.effects, model.piano)
    for other, other_drive in ((stiffer, drive), (model, {"acceleration_mps2": 1.2})):
        before = len(calls)
        kept.predict(other, other_drive)
        assert len(calls) > before
    for i in range(KEPT_SIMULATIONS + 1):
        kept.predict(model, {"acceleration_mps2": 2.0 + i})
    assert len(kept._kept) == KEPT_SIMULATIONS
    assert pickle.loads(pickle.dumps(kept))._kept == []  # a worker gets the drive, not its traces
