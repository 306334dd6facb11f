"""A fit's Jacobian simulates one model per perturbed parameter; the measured-arm drive runs
them side by side (`MeasuredArm.predict_many`). Every model's prediction, and so the Jacobian,
is bit for bit what simulating it alone gives."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest
from _synthetic_runs import linear_sweep

from pianobot.analysis.greybox.fitter import GreyBoxFit
from pianobot.analysis.greybox.forward import MeasuredArm
from pianobot.analysis.greybox.layout import base_layout
from pianobot.analysis.greybox.load import load_keystrokes
from pianobot.analysis.greybox.prediction import SIM_STEP_S, Prediction, integration_step
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.simulate import simulate_arm


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> MeasuredArm:
    """Presses of very different lengths (slow and fast), so rows of several models share blocks."""
    data = tmp_path_factory.mktemp("side-by-side") / "data"
    run = linear_sweep(data, seed=31, levels_kpa=(-40.0,), speeds_mps=(0.008, 0.025, 0.06), depths_m=(0.025,),
                       distance_m=0.004, repeats=2)
    return MeasuredArm.of(load_keystrokes([run], data).batch)


def _same(a: Prediction, b: Prediction) -> None:
    for name in ("x1_m", "x2_m", "v2_mps", "force_n"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_models_side_by_side_predict_what_each_predicts_alone(drive: MeasuredArm) -> None:
    study = KeystrokeModel.study()
    contact = study.replace(effects=study.effects.with_effect("contact"))
    models = [
        study,
        study.replace(msd=dataclasses.replace(study.msd, c1_nspm=study.msd.c1_nspm * 1.01)),
        contact,  # other effects: simulated in a set of its own
        study.replace(msd=dataclasses.replace(study.msd, k2_npm=3e5, c2_nspm=30.0)),  # another step
        # A hair stiffer: it asks for another step but takes the same one, and runs with those.
        study.replace(msd=dataclasses.replace(study.msd, k2_npm=3e5 * 1.001, c2_nspm=30.0)),
        contact.replace(msd=dataclasses.replace(study.msd, m1_kg=study.msd.m1_kg * 1.01)),
        study,  # the same model twice
    ]
    together = drive.predict_many(models)
    assert len(together) == len(models)
    for model, prediction in zip(models, together, strict=True):
        _same(prediction, drive.predict(model))
    assert np.isfinite(together[0].x2_m).any()


def test_models_asking_for_steps_a_hair_apart_run_together(drive: MeasuredArm, monkeypatch: pytest.MonkeyPatch) -> None:
    study = KeystrokeModel.study()
    stiff = [study.replace(msd=dataclasses.replace(study.msd, k2_npm=3e5 * f, c2_nspm=30.0)) for f in (1.0, 1.001)]
    asked = [integration_step(m, drive.batch.vacuum_kpa, SIM_STEP_S, drive.compression_m)[0] for m in stiff]
    assert asked[0] != asked[1] and asked[0] < SIM_STEP_S
    calls: list[int] = []
    original = MeasuredArm._simulate

    def counted(self: MeasuredArm, models: Any, *args: Any) -> Any:
        calls.append(len(models))
        return original(self, models, *args)

    monkeypatch.setattr(MeasuredArm, "_simulate", counted)
    drive.predict_many(stiff)
    assert calls == [2]


def test_the_jacobian_is_the_same_with_models_side_by_side(drive: MeasuredArm,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    layout = base_layout(KeystrokeModel.study(), [-40.0])
    theta = layout.start()
    fit = GreyBoxFit(drive, layout, sigma={"x1": 1e-5, "x2": 1e-5})
    forward, central = fit.jacobian(theta, central=False), fit.jacobian(theta)
    monkeypatch.setattr(MeasuredArm, "predict_many", None)  # one model at a time
    alone = GreyBoxFit(drive, layout, sigma={"x1": 1e-5, "x2": 1e-5})
    np.testing.assert_array_equal(forward, alone.jacobian(theta, central=False))
    np.testing.assert_array_equal(central, alone.jacobian(theta))
    assert np.abs(forward).max() > 0


def test_models_side_by_side_need_the_same_effects() -> None:
    study = KeystrokeModel.study()
    t = np.arange(0.0, 0.2, 1e-3)
    with pytest.raises(ValueError, match="same effects"):
        simulate_arm(t, np.zeros((2, t.size)), -40.0, [study, study.replace(effects=study.effects.with_effect("contact"))])


@pytest.mark.parametrize("costs", [{4: 1.0, 8: 8.0, 16: 16.0}, {4: 4.0, 8: 1.0, 16: 16.0}, {4: 4.0, 8: 8.0, 16: 1.0}])
def test_predictions_do_not_depend_on_the_block_costs_that_group_the_keystrokes(
        drive: MeasuredArm, costs: dict[int, float], monkeypatch: pytest.MonkeyPatch) -> None:
    """Costs that make the 4-, the 8- and then the 16-lane block the cheapest group the rows
    differently (`length_groups`); what this machine measures (`physics.lanes`) may do either."""
    import pianobot.analysis.greybox.forward as forward
    from pianobot.analysis.greybox.prediction import length_groups
    from pianobot.physics.simulate import block_for

    study = KeystrokeModel.study()
    models = [study, study.replace(msd=dataclasses.replace(study.msd, c1_nspm=study.msd.c1_nspm * 1.01))]
    reference = drive.predict_many(models)
    monkeypatch.setattr(forward, "block_costs", lambda *args, **kwargs: costs)
    cheapest = min(costs, key=lambda block: costs[block])
    lengths = np.tile(np.arange(1.0, drive.batch.n + 1.0) * 1e4, len(models))
    assert {block_for(rows.size) for rows in length_groups(lengths, costs)} == {cheapest}
    for model, prediction, again in zip(models, reference, drive.predict_many(models), strict=True):
        _same(prediction, again)
        _same(prediction, drive.predict(model))
