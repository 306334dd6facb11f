"""A keystroke's result never depends on the other keystrokes simulated in the same batch.

Bug report (identification): the same 0.22 m/s press read out at different on-velocities
depending on its batch companions. Batches share one time grid (to the longest press), run in
SIMD blocks of a compile-time size (a lone press takes the small block), and pick the arm
profile code per block; none of this may change a keystroke's own samples or readout.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pianobot.physics.effects import Effects
from pianobot.physics.linear import lsim_uniform, state_space
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.msd import MSDParams
from pianobot.physics.piano import key_events
from pianobot.physics.simulate import SimBatch, simulate_arm, simulate_presses
from pianobot.physics.trajectory import Press, sample_presses
from pianobot.physics.world import World, WorldConfig

PRESS = Press(0.05, 0.03, 0.22, 0.22, 1.0, 0.0)
SLOWER = Press(0.05, 0.03, 0.03, 0.03, 0.1, 0.0)
FASTER = Press(0.01, 0.02, 0.5, 0.7, 2.0, 0.0)
LONGER = Press(0.05, 0.03, 0.22, 0.22, 1.0, 1.5)
TRIANGLE = Press(0.0, 0.01, 0.4, 0.4, 0.1, 0.2)  # too short to reach its speed

MODELS = {
    "study": KeystrokeModel.study(),
    "world": World.default().model,
    "world_ramp": World.default().model.without("arm_acceleration"),
    "all_effects": KeystrokeModel(effects=Effects.all().without("finger_hysteresis")),
    # Its own kernel, with one more state per lane; a stiffer body, so the press still reaches
    # the lower sensor although the body yields (past 2 mm of its ~12 mm).
    "all_effects_yielding_body": KeystrokeModel(
        msd=MSDParams(k0_npm=250.0), effects=Effects.all().with_effect("finger_hysteresis", yield_m=0.002)),
}
SIGNALS = ("x0_m", "x1_m", "x2_m", "v2_mps", "contact_force_n")


def _assert_same_row(alone: SimBatch, batch: SimBatch, j: int) -> None:
    """Row j of `batch` equals the lone simulation on the lone simulation's samples, bit for bit."""
    T = alone.t_s.size
    assert batch.t_s.size >= T
    assert np.array_equal(batch.t_s[:T], alone.t_s)
    for name in SIGNALS:
        assert np.array_equal(getattr(batch, name)[j, :T], getattr(alone, name)[0]), name


def _on_speed(t_s: np.ndarray, x2_m: np.ndarray, model: KeystrokeModel) -> float:
    return key_events(t_s, x2_m, model.readout_params())[1]


@pytest.mark.parametrize("name", sorted(MODELS))
def test_a_press_is_the_same_alone_and_beside_slower_faster_and_longer_presses(name: str) -> None:
    model = MODELS[name]
    alone = simulate_presses([PRESS], -40.0, model)
    assert alone.x2_m.max() > 0.0038  # it reaches the lower sensor: there is a velocity to compare
    companions = [SLOWER, FASTER, LONGER, TRIANGLE]
    # Small batches (the small SIMD block) and large ones (several full blocks plus a partial
    # one), with the press in the first, a middle and the last lane.
    for size in (2, 4, 5, 16, 37):
        others = [companions[k % len(companions)] for k in range(size - 1)]
        for pos in sorted({0, size // 2, size - 1}):
            presses = [*others[:pos], PRESS, *others[pos:]]
            vacuum = np.linspace(-80.0, 0.0, size)
            vacuum[pos] = -40.0
            batch = simulate_presses(presses, vacuum, model)
            _assert_same_row(alone, batch, pos)
            assert _on_speed(batch.t_s, batch.x2_m[pos], model) == _on_speed(
                alone.t_s, alone.x2_m[0], model
            )


def test_a_ramp_press_beside_accelerating_presses_keeps_its_own_profile() -> None:
    """Ramp and trapezoid presses mixed in one block: each keeps its own arm motion."""
    model = KeystrokeModel.study()
    ramp = simulate_presses([PRESS], -40.0, model)
    trapezoid = simulate_presses([PRESS], -40.0, model.with_effect("arm_acceleration"))
    x_ramp, _ = sample_presses([PRESS], ramp.t_s, profile="ramp")
    x_trap, _ = sample_presses([PRESS], trapezoid.t_s, profile="trapezoid")
    assert np.max(np.abs(ramp.x0_m[0] - x_ramp[0])) < 1e-12
    assert np.max(np.abs(trapezoid.x0_m[0] - x_trap[0])) < 1e-12
    # At 0.1 m/s² the arm never reaches 0.22 m/s: the two profiles must not be confused.
    slow_acc = Press(0.05, 0.03, 0.22, 0.22, 0.1, 0.0)
    b = simulate_presses([slow_acc, PRESS], -40.0, model.with_effect("arm_acceleration"))
    x, _ = sample_presses([slow_acc, PRESS], b.t_s, profile="trapezoid")
    assert np.max(np.abs(b.x0_m - x)) < 1e-12


def test_arm_traces_are_simulated_independently_of_their_batch() -> None:
    t = np.arange(0.0, 2.5, 2e-3)
    presses = [PRESS, SLOWER, FASTER, LONGER, TRIANGLE] * 4
    x0, _ = sample_presses(presses, t)
    distance = np.array([p.distance_m for p in presses])
    vacuum = np.linspace(-80.0, -10.0, len(presses))
    model = MODELS["world"]
    batch = simulate_arm(t, x0, vacuum, model, distance_m=distance)
    for j in (0, 7, 19):
        alone = simulate_arm(t, x0[j], vacuum[j], model, distance_m=distance[j])
        _assert_same_row(alone, batch, j)


def test_world_keystrokes_equal_one_keystroke_at_a_time() -> None:
    """`World.keystrokes` promises the results of `World.keystroke` for each press."""
    world = World(WorldConfig(), seed=3)
    presses = [Press(0.05, 0.03, 0.06, 0.06, 1.0, 0.0), Press(0.05, 0.03, 0.01, 0.01, 1.0, 0.5)]
    together = world.keystrokes(presses, -60.0, keys=["a", "b"])
    for press, key, got in zip(presses, ("a", "b"), together, strict=True):
        alone = world.keystroke(press, -60.0, key=key)
        assert got.duration_s == alone.duration_s
        assert got.midi == alone.midi
        for field in ("truth_t_s", "truth_x2_m", "arm_x0_m", "mocap_t_s", "mocap_x1_m"):
            assert np.array_equal(getattr(got, field), getattr(alone, field), equal_nan=True), field
        assert got.key_speed_at_trigger_mps == alone.key_speed_at_trigger_mps or (
            math.isnan(got.key_speed_at_trigger_mps) and math.isnan(alone.key_speed_at_trigger_mps)
        )


def test_lsim_rows_do_not_depend_on_their_companions() -> None:
    """A system without static equilibrium (k0 = k2 = 0: the finger and key float) starting at
    rest simulates beside one that starts displaced, and each row is what it is alone."""
    params = [MSDParams(k0_npm=0.0, k2_npm=0.0).at(-40.0), MSDParams().at(-40.0)]
    systems = [state_space(lp) for lp in params]
    t = np.arange(0.0, 0.5, 1e-3)
    u = np.stack([np.minimum(t, 0.1), 0.01 + np.minimum(t, 0.1)])[:, None, :]
    stacked = type(systems[0])(*(np.stack([getattr(s, m) for s in systems]) for m in "ABCD"))
    together = lsim_uniform(stacked, t, u)
    for j, ss in enumerate(systems):
        assert np.allclose(together[j], lsim_uniform(ss, t, u[j]), rtol=0.0, atol=1e-15)
