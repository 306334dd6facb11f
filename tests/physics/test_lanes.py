"""`physics.lanes`: the integrator's block costs, measured on this machine for each kernel."""

from __future__ import annotations

import dataclasses

import pytest

from pianobot.physics import _kernel as K
from pianobot.physics import lanes
from pianobot.physics.lanes import block_costs
from pianobot.physics.model import KeystrokeModel


@pytest.mark.parametrize("trace", [False, True])
@pytest.mark.parametrize("effects", ["linear", "contact", "power"])
def test_block_costs_are_ordered_and_bounded_by_the_lanes(trace: bool, effects: str) -> None:
    model = KeystrokeModel.study()
    if effects != "linear":
        model = model.replace(effects=model.effects.with_effect("contact"))
    if effects == "power":
        model = model.replace(effects=model.effects.with_effect("finger_stiffening", form="power"))
    costs = block_costs(model, trace=trace)
    assert list(costs) == list(K.BLOCKS)
    assert costs[K.SMALL_BLOCK] == 1.0
    ordered = [costs[block] for block in K.BLOCKS]
    assert ordered == sorted(ordered)
    assert all(costs[block] <= block / K.SMALL_BLOCK for block in K.BLOCKS)


def test_block_costs_are_measured_once_per_kernel(monkeypatch: pytest.MonkeyPatch) -> None:
    """A model of the same kernel (other values) gets the kept costs, another kernel (implicit
    dampers) its own; the caller's copy can be changed without touching them."""
    measured: list[bool] = []

    def measure(model: KeystrokeModel, trace: bool, implicit: bool) -> dict[int, float]:
        measured.append(implicit)
        return {block: 1.0 + i for i, block in enumerate(K.BLOCKS)}

    monkeypatch.setattr(lanes, "_measured", {})
    monkeypatch.setattr(lanes, "_measure", measure)
    study = KeystrokeModel.study()
    first = block_costs(study, trace=True)
    first[K.BLOCK] = -1.0
    stiffer = study.replace(msd=dataclasses.replace(study.msd, k2_npm=2 * study.msd.k2_npm))
    assert block_costs(stiffer, trace=True)[K.BLOCK] == 3.0
    block_costs(stiffer, trace=True, implicit=True)
    block_costs(study, trace=False)
    assert measured == [False, True, False]
