"""The commanded drive reads a model that differs only in its readout from key traces it has
already simulated: the same MIDI outcomes as simulating again, without the simulation."""

from __future__ import annotations

import pickle
from dataclasses import replace

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


def _outcomes_by_masks(x2: np.ndarray, valid: np.ndarray, piano: commanded.PianoParams, dt: float) -> np.ndarray:
    """midi_outcomes as boolean masks over whole traces (how it was written before the compiled scan)."""
    def first(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.argmax(mask, axis=1), mask.any(axis=1)

    def cross(x: np.ndarray, k: np.ndarray, level: float) -> np.ndarray:
        rows, k = np.arange(x.shape[0]), np.maximum(k, 1)
        a, b = x[rows, k - 1], x[rows, k]
        with np.errstate(divide="ignore", invalid="ignore"):
            frac = np.where(b != a, (level - a) / (b - a), 0.0)
        return (k - 1 + np.clip(frac, 0.0, 1.0)) * dt

    x = np.where(valid, x2, -np.inf)
    margin = np.max(x, axis=1) - piano.lower_sensor_m
    k_up, _ = first(x >= piano.upper_sensor_m)
    k_lo, sounded = first(x >= piano.lower_sensor_m)
    t_up, t_on = cross(x, k_up, piano.upper_sensor_m), cross(x, k_lo, piano.lower_sensor_m)
    speed = (piano.lower_sensor_m - piano.upper_sensor_m) / np.maximum(t_on - t_up, 1e-6)
    velocity = commanded.on_velocity_from_speed(speed, piano, rounded=False, clipped=False)
    k_off, released = first((np.arange(x.shape[1])[None, :] > k_lo[:, None]) & valid & (x2 <= piano.release_m))
    rows = np.arange(x.shape[0])
    a, b = x2[rows, np.maximum(k_off - 1, 0)], x2[rows, k_off]
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.clip(np.where(a != b, (a - piano.release_m) / (a - b), 0.0), 0.0, 1.0)
    hold = np.where(released, (k_off - 1 + frac) * dt - t_on, np.nan)
    return np.stack([np.where(sounded, velocity, np.nan), np.where(sounded, t_on, np.nan),
                     np.where(sounded, hold, np.nan), margin])


def test_the_compiled_crossing_scan_reads_what_the_whole_trace_masks_read() -> None:
    """Simulated key traces (sounded, silent, never released), plus the edge cases of the scan:
    no valid sample, a key that never reaches a sensor, one that starts below them."""
    study = KeystrokeModel.study()
    model = study.__class__(study.msd, study.effects.with_effect("arm_acceleration"), study.piano)
    piano = model.readout_params()
    n = 20
    deep = KeystrokeBatch(
        tuple(f"k{i}" for i in range(n)), np.full(n, -60.0), np.zeros(0), np.zeros((n, 0)), np.zeros((n, 0)),
        np.zeros((n, 0)), down_velocity_mps=np.linspace(0.01, 0.08, n), up_velocity_mps=np.full(n, np.nan),
        acceleration_mps2=np.full(n, np.nan), depth_m=np.linspace(0.005, 0.04, n), hold_s=np.zeros(n),
        distance_m=np.full(n, 0.02))
    groups = Commanded(deep).key_traces(model, 0.6)
    rng = np.random.default_rng(8)
    x2 = rng.uniform(-0.002, 0.012, (6, 300))
    valid = rng.uniform(size=(6, 300)) < 0.9
    valid[0] = False
    x2[1] = 0.001
    x2[2, :] = 0.011
    cases = [(x, v) for _, _, x, v in groups] + [(x2, valid)]
    for x, v in cases:
        got = np.stack(commanded.midi_outcomes(x, v, piano, 1e-3))
        np.testing.assert_array_equal(got, _outcomes_by_masks(x, v, piano, 1e-3))
    velocity = [commanded.midi_outcomes(x, v, piano, 1e-3)[0] for x, v in cases[:-1]]
    assert any(np.isfinite(o).any() for o in velocity) and any(np.isnan(o).any() for o in velocity)


def test_a_sounded_note_is_never_predicted_softer_than_the_piano_sends() -> None:
    """A piano sends a sounded note at velocity 1 at least. The commanded drive's prediction has
    that floor, smoothly (a fit keeps a slope below it): a model whose key speeds map to tenths
    of a unit predicts about 1, as the piano would send, and loud notes are left as they were.
    Before, the slowest keystrokes of the study's soft log (velocity 1) read as model errors of
    up to one unit each."""
    study = KeystrokeModel.study()
    drive = {"acceleration_mps2": 0.8}
    deep = replace(_batch(), depth_m=np.full(12, 0.03))  # the study's depths: every key sounds
    loud = Commanded(deep).predict(study, drive).on_velocity
    soft_piano = study.piano.replace(full_scale_speed_mps=1e3 * study.piano.full_scale_speed_mps)
    soft = Commanded(deep).predict(study.__class__(study.msd, study.effects, soft_piano), drive).on_velocity
    sounded = np.isfinite(soft)
    assert sounded.all() and np.all(loud / 1e3 < 0.5)  # the map is linear in speed: 1/1000 of it
    assert np.all((soft >= 1.0) & (soft < 1.01))
    assert np.all(np.abs(commanded.velocity_floor(loud[loud > 3]) - loud[loud > 3]) < 1e-3)
    floor = commanded.velocity_floor(np.array([-5.0, 0.0, 1.0, 2.0, 40.0]))
    assert np.all(np.diff(floor) > 0) and floor[0] >= 1.0 and abs(floor[-1] - 40.0) < 1e-12
