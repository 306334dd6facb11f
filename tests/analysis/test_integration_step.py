"""The grey-box fit's integration step: as large as the model allows, never unstable.

A fit may try heavily damped or stiff parameters (a base model imitating an end stop runs its
key damping to the bound); the step follows the model's exact time scales, and the simulation at
that step matches one at a far finer step to well below mocap noise.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pianobot.analysis.greybox.prediction import (
    GROUP,
    IMPLICIT_GAIN,
    STEP_PER_DAMPING_TIME,
    integration_step,
    integration_step_s,
    length_groups,
)
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.simulate import simulate_arm

LARGEST_S = 2e-4
LEVELS = np.array([-40.0])


def _press(model: KeystrokeModel, step_s: float, implicit: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """A 12 mm press at 40 mm/s from 2 mm above the key, held, released (1 ms output)."""
    t = np.arange(0.0, 1.2, 1e-3)
    arm = np.clip(0.04 * (t - 0.05), 0.0, 0.012) - np.clip(0.04 * (t - 0.7), 0.0, 0.012)
    sim = simulate_arm(t, arm[None, :], LEVELS, model, distance_m=0.002, out_dt_s=1e-3, step_s=step_s,
                       implicit_damping=implicit)
    return sim.x1_m[0], sim.x2_m[0]


#: A base fit bent into dampers hundreds of times the finger's (measured on an independent
#: stiffening take): the explicit step is ~13 µs.
BENT = {"m1_kg": 0.007, "c1_nspm": 147.0, "c0_over_c1": 0.71, "c2_nspm": 234.0, "k1_a_npm": 61.4, "k2_npm": 180.0}


def test_heavily_damped_models_take_the_implicit_dampers_at_the_springs_step() -> None:
    study = KeystrokeModel.study()
    assert integration_step(study, LEVELS, LARGEST_S) == (LARGEST_S, False)
    for fx in (study.effects, study.with_effect("contact").with_effect("keybed").effects):
        model = study.replace(msd=dataclasses.replace(study.msd, **BENT), effects=fx)
        explicit = integration_step_s(model, LEVELS, LARGEST_S)
        step, implicit = integration_step(model, LEVELS, LARGEST_S)
        assert implicit and step >= IMPLICIT_GAIN * explicit and explicit < 2e-5


@pytest.mark.parametrize("effects", [
    (),
    ("contact",),
    ("contact", "keybed", "key_friction", "adhesion"),
    ("contact", "key_preload", "letoff", "finger_stiffening"),
    ("contact", "key_friction/stribeck", "finger_hysteresis", "adhesion/cohesive"),
    ("contact", "key_preload/smooth", "finger_stiffening/power", "keybed/hunt_crossley"),
])
def test_implicit_dampers_at_the_large_step_match_the_explicit_scheme_at_a_fine_one(effects: tuple[str, ...]) -> None:
    """The implicit scheme at the springs' step (16x the explicit limit here) against the explicit
    one at a quarter of its own limit, with unilateral contact, a bed, dry friction, a rest stop,
    a let-off, a yielding body and a skin in play: within 1 µm RMS, 5 µm at worst (mocap noise
    is ~3 µm RMS). With normal dampers, at the same step, it is as accurate as the explicit
    scheme."""
    study = KeystrokeModel.study()
    for changes in (BENT, {}):
        model = study.replace(msd=dataclasses.replace(study.msd, **changes))
        for label in effects:
            name, _, form = label.partition("/")
            model = model.with_effect(name, **({"form": form} if form else {}))
        step, implicit = integration_step(model, LEVELS, LARGEST_S)
        assert implicit == bool(changes)
        r1, r2 = _press(model, integration_step_s(model, LEVELS, LARGEST_S) / 4)
        x1, x2 = _press(model, step, implicit=True)
        assert np.all(np.isfinite(x1)) and np.all(np.isfinite(x2))
        assert np.max(np.abs(r2)) > 3e-4  # the key went down
        err = np.concatenate([x1 - r1, x2 - r2])
        if changes:
            assert np.sqrt(np.mean(err**2)) < 1e-6 and np.max(np.abs(err)) < 5e-6
        else:
            e1, e2 = _press(model, step)
            explicit = np.max(np.abs(np.concatenate([e1 - r1, e2 - r2])))
            assert np.max(np.abs(err)) < 1.2 * explicit + 1e-8


def test_the_published_model_takes_the_largest_step() -> None:
    assert integration_step_s(KeystrokeModel.study(), LEVELS, LARGEST_S) == LARGEST_S


@pytest.mark.parametrize("changes", [
    {"c1_nspm": 87.0, "c2_nspm": 300.0, "c0_over_c1": 1.36, "m1_kg": 0.007},  # damping-limited
    {"k2_npm": 3e5, "c2_nspm": 30.0},  # a stiff key: oscillation-limited
])
def test_a_stiff_or_heavily_damped_model_is_stable_and_accurate_at_its_step(changes: dict[str, float]) -> None:
    study = KeystrokeModel.study()
    model = study.replace(msd=dataclasses.replace(study.msd, **changes))
    step = integration_step_s(model, LEVELS, LARGEST_S)
    assert step < LARGEST_S
    x1, x2 = _press(model, step)
    r1, r2 = _press(model, step / 20)
    assert np.all(np.isfinite(x1)) and np.all(np.isfinite(x2))
    assert max(np.max(np.abs(x1 - r1)), np.max(np.abs(x2 - r2))) < 1e-6  # far below mocap noise (~10 µm)


def test_the_damping_limit_keeps_a_margin_to_instability() -> None:
    """At twice the step (the scheme's measured limit h·λ ≈ 1) a heavily damped model is unstable:
    the margin is real, not a formality."""
    study = KeystrokeModel.study()
    model = study.replace(msd=dataclasses.replace(study.msd, c1_nspm=87.0, c2_nspm=300.0, c0_over_c1=1.36,
                                                  m1_kg=0.007))
    step = integration_step_s(model, LEVELS, LARGEST_S)
    with np.errstate(all="ignore"):
        x1, _ = _press(model, 2.2 * step)
    assert STEP_PER_DAMPING_TIME * 2.2 > 1.0
    assert not np.all(np.abs(x1) < 1.0)  # blew up (or overflowed to inf/NaN)


@pytest.mark.parametrize(("per_m", "exponent"), [(800.0, 4.0), (1000.0, 4.0)])
def test_a_sharply_stiffening_finger_is_judged_where_it_is_compressed(per_m: float, exponent: float) -> None:
    """A power-law finger k1·δ·(1 + (βδ)^q) is stiff only where it is compressed. Judged at the
    compression the press reaches (what a fit measures on the take), the step is several times
    larger than at the 5 mm assumed without a fingertip trace, and still accurate to far below
    noise."""
    model = KeystrokeModel.study().with_effect("contact").with_effect(
        "finger_stiffening", form="power", stiffening_per_m=per_m, stiffening_exponent=exponent)
    r1, r2 = _press(model, 2e-6)
    reached = float(np.max(r1 - r2 - 0.002))
    assert reached < 2e-3
    step = integration_step_s(model, LEVELS, LARGEST_S, reached)
    assert step > 2.5 * integration_step_s(model, LEVELS, LARGEST_S)
    x1, x2 = _press(model, step)
    assert max(np.max(np.abs(x1 - r1)), np.max(np.abs(x2 - r2))) < 1e-6


def _cost(groups: list[np.ndarray], lengths: np.ndarray) -> float:
    from pianobot.analysis.greybox.prediction import CALL_COST_STEPS, PROPORTIONAL_COSTS
    from pianobot.physics.simulate import block_for

    return sum(PROPORTIONAL_COSTS[block_for(g.size)] * float(lengths[g].max()) + CALL_COST_STEPS for g in groups)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(1.0, 1e5), min_size=1, max_size=60))
def test_length_groups_cover_every_row_once_at_no_more_cost_than_blocks_of_16(raw: list[float]) -> None:
    lengths = np.asarray(raw)
    groups = length_groups(lengths)
    rows = np.concatenate(groups)
    assert sorted(rows.tolist()) == list(range(lengths.size))
    assert all(0 < g.size <= GROUP for g in groups)
    order = np.argsort(-lengths, kind="stable")
    blocks = [order[i : i + GROUP] for i in range(0, order.size, GROUP)]
    assert _cost(groups, lengths) <= _cost(blocks, lengths) + 1e-6


def test_length_groups_keep_the_long_presses_of_a_take_away_from_its_short_ones() -> None:
    """A take's 16 training presses: two slow ones of 14 s, the rest 2.5-7.5 s."""
    lengths = np.array([14.3, 14.3, 7.5, 7.5, 5.2, 5.2, 4.1, 4.1, 3.4, 3.4, 3.0, 3.0, 2.7, 2.7, 2.5, 2.5]) / 5e-4
    groups = length_groups(lengths)
    first = groups[0]
    assert set(first.tolist()) >= {0, 1} and first.size <= 4  # the slow pair runs in the small kernel
    assert _cost(groups, lengths) < 0.8 * _cost([np.arange(16)], lengths)
