"""The compiled kernel's two model classes share one scaffold and must agree where both apply.

The linear kernel is the full kernel with every finger- and key-side effect removed at compile
time. On a model with none of those effects both integrate the same equations with the same
scheme, so their samples may differ only by rounding (the full step computes the key's
acceleration from its velocity change, the linear one directly); 1e-12 in metres (and in N, m/s)
is about a thousand times the rounding seen, and a million times smaller than any modelling
difference. Every arm input the kernel has is covered: analytic presses (plain, trapezoid,
two-segment), a lagged or delayed arm, and measured traces.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from pianobot.physics import _kernel as K
from pianobot.physics.approach import ApproachSettings, fast_press
from pianobot.physics.effects import Effects
from pianobot.physics.msd import MSDParams
from pianobot.physics.simulate import effect_vector, press_columns
from pianobot.physics.trajectory import Press, press_timing

AGREE = 1e-12
STEP_S = 1e-4
OUT_EVERY = 10  # 1 ms outputs
N_STEPS = 6000  # 0.6 s, unless a test needs longer


def _presses(n: int, rng: np.random.Generator) -> list[Press]:
    return [
        Press(float(rng.uniform(0.0, 0.004)), float(rng.uniform(0.004, 0.01)),
              float(rng.uniform(0.02, 0.12)), float(rng.uniform(0.02, 0.12)), 1.5, 0.05)
        for _ in range(n)
    ]


def _constants(presses: list[Press], vacuum_kpa: np.ndarray, profile: str) -> np.ndarray:
    """The kernel's parameter table: the study's model at each vacuum level, with its presses."""
    kp, _ = press_columns(presses, profile)
    msd = MSDParams(m1_kg=0.055, c1_nspm=0.8, k2_npm=420.0)  # not the defaults: any linear model
    for j, p in enumerate(vacuum_kpa):
        lp = msd.at(float(p))
        kp[j, : K.DIST] = (lp.m1_kg, lp.m2_kg, lp.k0_npm, lp.c0_nspm, lp.k1_npm, lp.c1_nspm,
                           lp.k2_npm, lp.c2_nspm)
    return kp


def _run(kernels: dict[int, object], kp: np.ndarray, ep: np.ndarray, mode: int,
         trace_t: np.ndarray, trace_x0: np.ndarray, n_steps: int = N_STEPS) -> list[np.ndarray]:
    n = kp.shape[0]
    n_out = n_steps // OUT_EVERY + 1
    outs = [np.full((n, n_out), np.nan) for _ in range(5)]
    kernel = kernels[K.SMALL_BLOCK if n <= K.SMALL_BLOCK else K.BLOCK]
    kernel(kp, ep, mode, trace_t, trace_x0, 0.0, STEP_S, n_steps, OUT_EVERY, *outs)  # type: ignore[operator]
    return outs


def _assert_agree(kp: np.ndarray, ep: np.ndarray, mode: int, trace_t: np.ndarray | None = None,
                  trace_x0: np.ndarray | None = None, n_steps: int = N_STEPS) -> None:
    n = kp.shape[0]
    t = np.zeros(1) if trace_t is None else trace_t
    x = np.zeros((1, n)) if trace_x0 is None else trace_x0
    full = _run(K.integrate, kp, ep, mode, t, x, n_steps)
    linear = _run(K.integrate_linear, kp, ep, mode, t, x, n_steps)
    for name, a, b in zip(("x0", "x1", "x2", "v2", "contact force"), full, linear, strict=True):
        assert np.all(np.isfinite(a)) and np.all(np.isfinite(b)), name
        assert np.max(np.abs(a - b)) <= AGREE, (name, float(np.max(np.abs(a - b))))
    # The comparison means something: the key moved and the finger pushed it.
    assert np.max(full[2]) > 2e-4 and np.max(np.abs(full[4])) > 0.05


@pytest.mark.parametrize("n", [1, 3, 21])  # one small block; two full blocks, one partial
@pytest.mark.parametrize("profile", ["ramp", "trapezoid"])
def test_linear_and_full_kernels_agree_on_analytic_presses(n: int, profile: str) -> None:
    rng = np.random.default_rng(n)
    presses = _presses(n, rng)
    kp = _constants(presses, rng.uniform(-80.0, 0.0, n), profile)
    _assert_agree(kp, effect_vector(Effects()), 0)


def test_linear_and_full_kernels_agree_on_two_segment_presses() -> None:
    rng = np.random.default_rng(7)
    presses = [fast_press(Press(0.03, float(rng.uniform(0.004, 0.01)), v, v, 1.5, 0.05),
                          ApproachSettings(settle_s=0.1)) for v in rng.uniform(0.02, 0.045, 5)]
    assert all(p.two_segment for p in presses)
    t_end_s = max(press_timing(p, "trapezoid").t_end_s for p in presses)
    kp = _constants(presses, rng.uniform(-80.0, 0.0, 5), "trapezoid")
    _assert_agree(kp, effect_vector(Effects()), 2, n_steps=int(t_end_s / STEP_S) + 1000)


@pytest.mark.parametrize("form, lag_s", [("first_order", 0.012), ("delay", 0.02)])
def test_linear_and_full_kernels_agree_with_a_lagging_arm(form: str, lag_s: float) -> None:
    rng = np.random.default_rng(3)
    presses = _presses(6, rng)
    kp = _constants(presses, rng.uniform(-80.0, 0.0, 6), "ramp")
    ep = effect_vector(Effects().with_effect("arm_lag", form=form, arm_lag_s=lag_s))
    assert ep[K.E_LAG_S] == lag_s
    _assert_agree(kp, ep, 0)


def test_linear_and_full_kernels_agree_on_measured_arm_traces() -> None:
    rng = np.random.default_rng(11)
    n = 5
    t = np.arange(0.0, 0.7, 2e-3)
    # Smooth bumps of random depth and timing, plus a little jitter like a mocap trace.
    centre = rng.uniform(0.15, 0.35, n)
    depth = rng.uniform(0.005, 0.012, n)
    x = depth * np.exp(-(((t[:, None] - centre) / 0.06) ** 2)) + rng.normal(0.0, 2e-5, (t.size, n))
    kp = _constants(_presses(n, rng), rng.uniform(-80.0, 0.0, n), "ramp")
    kp[:, K.DIST] = 0.0
    _assert_agree(kp, effect_vector(Effects()), 1, t, np.ascontiguousarray(x))


def test_the_full_kernel_differs_once_an_effect_acts() -> None:
    """The agreement above is not vacuous: the same comparison sees a key-side effect."""
    rng = np.random.default_rng(5)
    presses = _presses(3, rng)
    kp = _constants(presses, rng.uniform(-80.0, 0.0, 3), "ramp")
    ep = effect_vector(Effects().with_effect("key_friction", friction_n=0.05))
    full = _run(K.integrate, kp, ep, 0, np.zeros(1), np.zeros((1, 3)))
    linear = _run(K.integrate_linear, kp, ep, 0, np.zeros(1), np.zeros((1, 3)))
    assert np.max(np.abs(full[2] - linear[2])) > 1e-5


_CACHE_PROBE = """
import json
from pianobot.physics import _kernel as K
from pianobot.physics.effects import Effects
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.simulate import simulate_presses
from pianobot.physics.trajectory import Press
presses = [Press(0.0, 0.008, 0.05, 0.05, 1.0, 0.0)]
power = Effects.all().with_effect("finger_stiffening", form="power")
for model in (KeystrokeModel.study(), KeystrokeModel(effects=Effects.all()), KeystrokeModel(effects=power)):
    for n in (1, K.BLOCK + 1):  # both block sizes
        simulate_presses(presses * n, -40.0, model, duration_s=0.02)
print(json.dumps({f"{name}-{b}": [sum(f.stats.cache_hits.values()), sum(f.stats.cache_misses.values())]
                  for name, kernels in (("full", K.integrate), ("linear", K.integrate_linear),
                                        ("power", K.integrate_power))
                  for b, f in kernels.items()}))
"""


def test_every_kernel_comes_from_numbas_disk_cache() -> None:
    """The six kernels (two block sizes × linear/full/full with a power-law finger) share one
    factory; each must be cached.

    numba keys a closure's cache entry on its frozen values, so a fresh process (the second
    run; the first fills the cache if this source changed) loads all six from disk instead of
    compiling them, which is what keeps `pianobot` start-up and every test worker fast.
    """
    for _ in range(2):
        done = subprocess.run([sys.executable, "-c", _CACHE_PROBE], capture_output=True, text=True,
                              check=True, timeout=600)
    stats = json.loads(done.stdout.strip().splitlines()[-1])
    assert stats == {f"{kind}-{b}": [1, 0] for kind in ("full", "linear", "power") for b in (K.SMALL_BLOCK, K.BLOCK)}
