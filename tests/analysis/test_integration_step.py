"""The grey-box fit's integration step: as large as the model allows, never unstable.

A fit may try heavily damped or stiff parameters (a base model imitating an end stop runs its
key damping to the bound); the step follows the model's exact time scales, and the simulation at
that step matches one at a far finer step to well below mocap noise.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pianobot.analysis.greybox.prediction import STEP_PER_DAMPING_TIME, integration_step_s
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.simulate import simulate_arm

LARGEST_S = 2e-4
LEVELS = np.array([-40.0])


def _press(model: KeystrokeModel, step_s: float) -> tuple[np.ndarray, np.ndarray]:
    """A 12 mm press at 40 mm/s from 2 mm above the key, held, released (1 ms output)."""
    t = np.arange(0.0, 1.2, 1e-3)
    arm = np.clip(0.04 * (t - 0.05), 0.0, 0.012) - np.clip(0.04 * (t - 0.7), 0.0, 0.012)
    sim = simulate_arm(t, arm[None, :], LEVELS, model, distance_m=0.002, out_dt_s=1e-3, step_s=step_s)
    return sim.x1_m[0], sim.x2_m[0]


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
