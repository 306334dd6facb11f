"""The compiled kernel's model classes share one scaffold and must agree where both apply.

The linear kernel is the full kernel with every finger- and key-side effect removed at compile
time. On a model with none of those effects both integrate the same equations with the same
scheme, so their samples may differ only by rounding (the full step computes the key's
acceleration from its velocity change, the linear one directly); 1e-12 in metres (and in N, m/s)
is about a thousand times the rounding seen, and a million times smaller than any modelling
difference. Every arm input the kernel has is covered: analytic presses (plain, trapezoid,
two-segment), a lagged or delayed arm, and measured traces. The kernel with a yielding finger
body (`finger_hysteresis`) is checked the same way against the full one, and its force law
through a loading-unloading cycle.
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
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.msd import MSDParams
from pianobot.physics.simulate import effect_vector, press_columns, simulate_arm
from pianobot.physics.trajectory import Press, press_timing

AGREE = 1e-12
STEP_S = 1e-4
# The full step's classes (flags power, hysteresis, smooth_stop, cohesive, implicit): with every
# effect, and with a yielding finger body.
PLAIN = (False, False, False, False, False)
HYSTERESIS = (False, True, False, False, False)
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
    full = _run(K.integrate_full[PLAIN], kp, ep, mode, t, x, n_steps)
    linear = _run(K.integrate_linear, kp, ep, mode, t, x, n_steps)
    for name, a, b in zip(("x0", "x1", "x2", "v2", "contact force"), full, linear, strict=True):
        assert np.all(np.isfinite(a)) and np.all(np.isfinite(b)), name
        assert np.max(np.abs(a - b)) <= AGREE, (name, float(np.max(np.abs(a - b))))
    # The comparison means something: the key moved and the finger pushed it.
    assert np.max(full[2]) > 2e-4 and np.max(np.abs(full[4])) > 0.05


@pytest.mark.parametrize("n", [1, 3, 6, 21])  # a 4-lane block; an 8-lane one; two 16-lane blocks, one partial
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
    full = _run(K.integrate_full[PLAIN], kp, ep, 0, np.zeros(1), np.zeros((1, 3)))
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
full = Effects.all().without("finger_hysteresis")
power = full.with_effect("finger_stiffening", form="power")
models = [KeystrokeModel.study()] + [KeystrokeModel(effects=fx) for fx in (full, power)]
models += [KeystrokeModel(effects=fx.with_effect("finger_hysteresis")) for fx in (full, power)]
for model in models:
    for n in (1, K.SMALL_BLOCK + 1, K.BLOCK + 1):  # every block size (4, 8, 16)
        simulate_presses(presses * n, -40.0, model, duration_s=0.02)
kinds = {"full": (False, False, False, False, False), "power": (True, False, False, False, False),
         "hysteresis": (False, True, False, False, False), "hysteresis_power": (True, True, False, False, False)}
print(json.dumps({f"{name}-{b}": [sum(f.stats.cache_hits.values()), sum(f.stats.cache_misses.values())]
                  for name, kernels in (("linear", K.integrate_linear),
                                        *((kind, K.integrate_full[flags]) for kind, flags in kinds.items()))
                  for b, f in kernels.items()}))
"""


def test_every_kernel_comes_from_numbas_disk_cache() -> None:
    """The fifteen kernels (three block sizes × linear/full/full with a power-law finger/full
    with a yielding body/both) share one factory; each must be cached.

    numba keys a closure's cache entry on its frozen values, so a fresh process (the second
    run; the first fills the cache if this source changed) loads all fifteen from disk instead of
    compiling them, which is what keeps `pianobot` start-up and every test worker fast.
    """
    for _ in range(2):
        done = subprocess.run([sys.executable, "-c", _CACHE_PROBE], capture_output=True, text=True,
                              check=True, timeout=600)
    stats = json.loads(done.stdout.strip().splitlines()[-1])
    kinds = ("full", "linear", "power", "hysteresis", "hysteresis_power")
    assert stats == {f"{kind}-{b}": [1, 0] for kind in kinds for b in K.BLOCKS}


# A yielding finger body (finger_hysteresis): its own kernel, the others untouched.

SHARE, YIELD_M = 0.5, 0.005
FRESH = Effects().with_effect("finger_hysteresis", yield_share=SHARE, yield_m=YIELD_M, yield_set=0.0)


def _cycle(effects: Effects) -> tuple[np.ndarray, np.ndarray, np.ndarray, MSDParams]:
    """The finger resting on the key, the arm pressed 30 mm down and back up slowly (1 s each
    way, so inertia and damping are small): body deflection u = x0 − x1 and the force through
    the body (contact force + m1·a1 − c0·(v0 − v1))."""
    t = np.arange(0.0, 2.0 + 1e-9, 1e-3)
    x0 = 0.03 * (1.0 - np.abs(t - 1.0))
    model = KeystrokeModel(effects=effects)
    b = simulate_arm(t, x0, -40.0, model)
    u = b.x0_m[0] - b.x1_m[0]
    v1, v0 = np.gradient(b.x1_m[0], t), np.gradient(b.x0_m[0], t)
    lp = model.msd.at(-40.0)
    spring = b.contact_force_n[0] + lp.m1_kg * np.gradient(v1, t) - lp.c0_nspm * (v0 - v1)
    return u, spring, b.contact_force_n[0], model.msd


def test_a_yielding_body_follows_the_elastoplastic_law_through_a_loop() -> None:
    """Loading: slope k0 up to the yield deflection, (1 − σ)·k0 past it; unloading: k0 again
    until the slider has slipped back 2·u_y, so the body keeps a set of u_y (with σ = ½) when its
    force is back to zero. The body force is the law applied to the simulated deflection."""
    u, spring, force, msd = _cycle(FRESH)
    k0 = msd.at(-40.0).k0_npm
    z = np.zeros_like(u)
    for i in range(1, u.size):  # the Jenkins element's return mapping, sample by sample
        z[i] = min(max(z[i - 1] + u[i] - u[i - 1], -YIELD_M), YIELD_M)
    law = k0 * ((1.0 - SHARE) * u + SHARE * z)
    assert np.max(np.abs(spring - law)[2:-2]) < 5e-3 * np.max(law)
    peak = int(np.argmax(u))
    assert u[peak] > 2.5 * YIELD_M  # the loop is a real one: the body yielded and came back
    # The slope of force over deflection: k0 below the yield, (1 − σ)·k0 above it (loading).
    du, df = np.diff(u[:peak]), np.diff(spring[:peak])
    moving = du > 1e-6
    below, above = moving & (u[1:peak] < 0.8 * YIELD_M), moving & (u[1:peak] > 1.2 * YIELD_M)
    assert np.median(df[below] / du[below]) == pytest.approx(k0, rel=0.02)
    assert np.median(df[above] / du[above]) == pytest.approx((1.0 - SHARE) * k0, rel=0.02)
    # Loading and unloading differ: at the same deflection the force is lower on the way back,
    # by σ·k0 times the slider's stretch there going down (yielded: u_y) and coming back (it
    # springs back from +u_y with the deflection, until it slips at −u_y).
    for mid in (0.4 * u[peak], 0.6 * u[peak]):
        down, up = np.interp(mid, u[:peak], spring[:peak]), np.interp(mid, u[peak:][::-1], spring[peak:][::-1])
        back = max(YIELD_M - (u[peak] - mid), -YIELD_M)
        assert down - up == pytest.approx(SHARE * k0 * (YIELD_M - back), rel=0.03)
    # The set the body keeps when its spring force is back to zero.
    zero = np.flatnonzero((np.arange(u.size) > peak) & (spring <= 0.0))[0]
    assert u[zero] == pytest.approx(YIELD_M, rel=0.03)
    assert np.min(force) < 0.0  # (the study's bilateral finger pulls the key back meanwhile)


def test_a_body_that_never_yields_is_the_linear_body_spring() -> None:
    """Off (σ = 0) the model runs the kernel it ran before the effect existed: the same numbers,
    bit for bit. On with σ > 0 but a yield above every deflection, the slider never slips, and
    the hysteresis kernel integrates the linear body to rounding."""
    linear = _cycle(Effects())
    off = _cycle(Effects().with_effect("finger_hysteresis", yield_share=0.0))
    for a, b in zip(linear[:3], off[:3], strict=True):
        assert np.array_equal(a, b)
    rigid = _cycle(FRESH.with_effect("finger_hysteresis", yield_m=0.05))
    assert np.max(np.abs(rigid[1] - linear[1])) < 1e-9
    assert np.max(np.abs(_cycle(FRESH)[1] - linear[1])) > 0.1


def test_a_body_that_yielded_before_starts_where_the_press_before_left_it() -> None:
    """`yield_set` is the state an earlier press leaves: a keystroke simulated with it is the
    second of two presses of a fresh body. The finger leaves the key on the way up (unilateral
    contact) and rests 2 s; at rest the body's force is zero, so its set u and its slider's
    stretch z hold (1 − σ)·u + σ·z = 0, and yield_set = −z/u_y. The fingertip hangs u higher
    above the key and has u_y·(1 + yield_set) of elastic range before the body yields again."""
    t = np.arange(0.0, 2.0 + 1e-9, 1e-3)
    press = 0.03 * (1.0 - np.abs(t - 1.0))
    twice = np.concatenate([press, np.zeros(2000), press[1:]])
    start = press.size + 2000 - 1  # the second press's first sample
    model = KeystrokeModel(effects=FRESH.with_effect("contact"))
    both = simulate_arm(np.arange(twice.size) * 1e-3, twice, -40.0, model)
    lifted = -both.x1_m[0, start]  # the fingertip above where it started the take: the set
    state = (1.0 - SHARE) * lifted / (SHARE * YIELD_M)
    assert 0.5 < state < 1.0  # the slider sprang back most of the way
    second = simulate_arm(t, press, -40.0, model.replace(
        effects=model.effects.with_effect("finger_hysteresis", yield_set=state)))
    assert np.max(np.abs(both.x1_m[0, start:] + lifted - second.x1_m[0])) < 2e-6
    assert np.max(np.abs(both.x2_m[0, start:] - second.x2_m[0])) < 2e-6
    assert np.max(np.abs(both.contact_force_n[0, start:] - second.contact_force_n[0])) < 1e-3
    # Not the first press: the fingertip travels its set before the key moves.
    moves = [int(np.argmax(x > 1e-5)) for x in (both.x2_m[0, : press.size], second.x2_m[0])]
    assert (moves[1] - moves[0]) * 1e-3 == pytest.approx(lifted / 0.03, rel=0.1)


def test_the_hysteresis_kernel_with_nothing_yielding_agrees_with_the_full_kernel() -> None:
    """The same comparison as linear/full above, one step up: every other effect on, the body's
    share 0, on analytic presses and measured traces."""
    rng = np.random.default_rng(17)
    presses = _presses(5, rng)
    kp = _constants(presses, rng.uniform(-80.0, 0.0, 5), "trapezoid")
    effects = Effects.all().without("finger_hysteresis").without("arm_lag")
    ep = effect_vector(effects)
    assert ep[K.E_HYST_SHARE] == 0.0
    for mode in (0, 1):
        t = np.arange(0.0, 0.7, 2e-3) if mode else np.zeros(1)
        x = (0.01 * np.sin(np.pi * np.clip(t, 0.0, 0.6) / 0.6)[:, None] * np.ones((1, 5)) if mode
             else np.zeros((1, 5)))
        full = _run(K.integrate_full[PLAIN], kp, ep, mode, t, np.ascontiguousarray(x))
        hyst = _run(K.integrate_full[HYSTERESIS], kp, ep, mode, t, np.ascontiguousarray(x))
        for a, b in zip(full, hyst, strict=True):
            assert np.all(np.isfinite(a)) and np.max(np.abs(a - b)) <= AGREE
