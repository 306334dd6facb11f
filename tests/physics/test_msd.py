"""The 2-DoF model: parameters, state space against the ODE, inverse, frequency response."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pianobot.physics.inverse import (
    inverse_arm_trajectory,
    inverse_state_space,
    inverse_trajectories,
)
from pianobot.physics.linear import frequency_response, peak_response, simulate_linear, state_space
from pianobot.physics.msd import (
    LinearParams,
    MSDParams,
    deformation_ratio,
    error_rate,
    static_deformation_ratio,
)

# Not the symmetric defaults: distinct k0, c0 catch swapped terms in the state space.
ASYMMETRIC = LinearParams(
    m1_kg=0.07,
    m2_kg=0.034,
    k0_npm=210.0,
    c0_nspm=0.8,
    k1_npm=140.0,
    c1_nspm=0.45,
    k2_npm=300.0,
    c2_nspm=0.3,
)


def _ode_rhs(lp: LinearParams, x0: float, v0: float, y: np.ndarray) -> np.ndarray:
    """The paper's equations of motion in the plain state [x1, ẋ1, x2, ẋ2]."""
    x1, v1, x2, v2 = y
    a1 = (
        lp.k0_npm * (x0 - x1)
        - lp.k1_npm * (x1 - x2)
        + lp.c0_nspm * (v0 - v1)
        - lp.c1_nspm * (v1 - v2)
    ) / lp.m1_kg
    a2 = (lp.k1_npm * (x1 - x2) - lp.k2_npm * x2 + lp.c1_nspm * (v1 - v2) - lp.c2_nspm * v2) / (
        lp.m2_kg
    )
    return np.array([v1, a1, v2, a2])


def _smooth_input(t: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A smooth press: x0 = D·sin²(πt/T)·(1 + 0.3 sin 40t) and its exact derivative."""
    depth, period = 0.02, 0.8
    t = np.asarray(t, dtype=np.float64)
    base = depth * np.sin(np.pi * t / period) ** 2
    dbase = depth * np.pi / period * np.sin(2 * np.pi * t / period)
    wob = 1 + 0.3 * np.sin(40 * t)
    return base * wob, dbase * wob + base * 12 * np.cos(40 * t)


@pytest.mark.parametrize("lp", [MSDParams().at(-60), ASYMMETRIC], ids=["published", "asym"])
def test_state_space_matches_equations_of_motion(lp: LinearParams) -> None:
    ss = state_space(lp)
    t_eval = np.linspace(0.0, 1.5, 301)
    tol = dict(rtol=1e-12, atol=1e-15, method="DOP853", t_eval=t_eval)

    def direct(t: float, y: np.ndarray) -> np.ndarray:
        x0, v0 = _smooth_input(t)
        return _ode_rhs(lp, float(x0), float(v0), y)

    def shifted(t: float, z: np.ndarray) -> np.ndarray:
        x0, _ = _smooth_input(t)
        return ss.A @ z + ss.B[:, 0] * float(x0)  # no ẋ0 needed

    ref = solve_ivp(direct, (0.0, 1.5), np.zeros(4), **tol).y  # type: ignore[arg-type]
    got = solve_ivp(shifted, (0.0, 1.5), np.zeros(4), **tol).y  # type: ignore[arg-type]
    y = ss.C @ got
    for row, name in ((0, "x1"), (2, "x2")):
        out = y[0] if name == "x1" else y[1]
        rel = np.max(np.abs(out - ref[row])) / np.max(np.abs(ref[row]))
        assert rel < 1e-6, name
    # The shifted velocity state really is ẋ1 − (c0/m1)·x0.
    x0, _ = _smooth_input(t_eval)
    np.testing.assert_allclose(got[1] + lp.c0_nspm / lp.m1_kg * x0, ref[1], atol=1e-9)
    assert ss.states[1] == "v1 - (c0/m1) x0" and ss.inputs == ("x0",)
    assert ss.outputs == ("x1", "x2")


def test_simulate_linear_is_exact_for_piecewise_linear_input() -> None:
    lp = ASYMMETRIC
    dt = 2e-3
    t = np.arange(0.0, 1.2, dt)
    knots_t, knots_x = [0.0, 0.3, 0.5, 0.9, 1.2], [0.0, 0.012, 0.012, 0.0, 0.0]
    x0 = np.interp(t, knots_t, knots_x)
    x1, x2 = simulate_linear(lp, t, x0)
    # Reference: the direct ODE integrated segment by segment (ẋ0 constant in each).
    y = np.zeros(4)
    ref = np.zeros((4, t.size))
    for k in range(len(knots_t) - 1):
        t_a, t_b = knots_t[k], knots_t[k + 1]
        v0 = (knots_x[k + 1] - knots_x[k]) / (t_b - t_a)
        inside = (t >= t_a - 1e-12) & (t < t_b - 1e-12)

        def rhs(
            tt: float, yy: np.ndarray, k: int = k, v0: float = v0, t_a: float = t_a
        ) -> np.ndarray:
            return _ode_rhs(lp, knots_x[k] + v0 * (tt - t_a), v0, yy)

        sol = solve_ivp(
            rhs, (t_a, t_b), y, rtol=1e-12, atol=1e-15, method="DOP853", dense_output=True
        )
        ref[:, inside] = sol.sol(t[inside])
        y = sol.y[:, -1]
    for got, want in ((x1, ref[0]), (x2, ref[2])):
        assert np.max(np.abs(got - want)) / np.max(np.abs(want)) < 1e-6


def test_batched_simulation_equals_single() -> None:
    lp = MSDParams().at(-40)
    t = np.arange(0.0, 0.5, 1e-3)
    traces = np.stack([0.01 * np.sin(5 * t) ** 2, np.interp(t, [0, 0.2, 0.5], [0, 0.02, 0.02])])
    x1, x2 = simulate_linear(lp, t, traces)
    assert x2.shape == (2, t.size)
    for i in range(2):
        _, x2_single = simulate_linear(lp, t, traces[i])
        np.testing.assert_allclose(x2[i], x2_single, rtol=1e-12, atol=1e-15)
    with pytest.raises(ValueError, match="uniformly"):
        simulate_linear(lp, np.array([0.0, 0.1, 0.3]), np.zeros(3))


def test_published_peak_near_nine_hz() -> None:
    peak_hz, peak_gain = peak_response(MSDParams().at(-60))
    assert peak_hz == pytest.approx(9.1, abs=0.1)
    assert peak_gain == pytest.approx(1.616, abs=0.005)
    # The resonance moves up as vacuum stiffens the finger.
    assert peak_response(MSDParams().at(-80))[0] > peak_response(MSDParams().at(0))[0]


@pytest.mark.parametrize("lp", [MSDParams().at(-60), ASYMMETRIC], ids=["published", "asym"])
def test_frequency_response_matches_state_space(lp: LinearParams) -> None:
    f = np.geomspace(0.1, 200, 50)
    h = state_space(lp).transfer(2j * np.pi * f)
    for col, name in ((0, "x1"), (1, "x2")):
        gain, phase = frequency_response(lp, f, output=name)
        np.testing.assert_allclose(gain, np.abs(h[:, col, 0]), rtol=1e-10)
        np.testing.assert_allclose(np.exp(1j * phase), h[:, col, 0] / np.abs(h[:, col, 0]))
    # Static gain of x2/x0: springs in series, k0 k1 / (k0 k1 + k0 k2 + k1 k2).
    k0, k1, k2 = lp.k0_npm, lp.k1_npm, lp.k2_npm
    g0, phase0 = frequency_response(lp, 0.0)
    assert float(phase0) == 0.0
    assert float(g0) == pytest.approx(k0 * k1 / (k0 * k1 + k0 * k2 + k1 * k2))


@pytest.mark.parametrize("lp", [MSDParams().at(-60), ASYMMETRIC], ids=["published", "asym"])
def test_inverse_is_the_reciprocal_transfer_function(lp: LinearParams) -> None:
    s = 2j * np.pi * np.geomspace(0.1, 500, 40)
    forward = state_space(lp).transfer(s)[:, 1, 0]
    inv = inverse_state_space(lp).transfer(s)[:, 0, :]  # x0 per unit of (x2, ẋ2, ẍ2)
    np.testing.assert_allclose(
        (inv[:, 0] + inv[:, 1] * s + inv[:, 2] * s**2) * forward, 1.0, rtol=1e-9
    )
    assert np.all(np.linalg.eigvals(inverse_state_space(lp).A).real < 0)


def _key_bump(t: np.ndarray, depth: float = 0.008, dur: float = 0.6) -> tuple[np.ndarray, ...]:
    """A C² key press: x2 = D·sin⁴(πt/dur) on [0, dur], with exact ẋ2 and ẍ2."""
    w = np.pi / dur
    on = t <= dur
    s, c = np.sin(w * t), np.cos(w * t)
    x = np.where(on, depth * s**4, 0.0)
    v = np.where(on, 4 * depth * w * s**3 * c, 0.0)
    a = np.where(on, depth * w**2 * (12 * s**2 * c**2 - 4 * s**4), 0.0)
    return x, v, a


def _round_trip_error(lp: LinearParams, dt: float, *, spline: bool = False) -> float:
    t = np.arange(0.0, 1.0, dt)
    x2, v2, a2 = _key_bump(t)
    if spline:
        x0 = inverse_arm_trajectory(lp, t, x2)
    else:
        x0 = inverse_arm_trajectory(lp, t, x2, v2_mps=v2, a2_mps2=a2)
    _, x2_back = simulate_linear(lp, t, x0)
    # The arm must lead and overshoot the key: it pushes through a finger spring.
    assert np.max(x0) > np.max(x2)
    return float(np.max(np.abs(x2_back - x2)) / np.max(x2))


@pytest.mark.parametrize("lp", [MSDParams().at(-60), ASYMMETRIC], ids=["published", "asym"])
def test_forward_of_inverse_returns_the_key_trajectory(lp: LinearParams) -> None:
    assert _round_trip_error(lp, 1e-4) < 1e-4
    # Without given derivatives a cubic spline supplies them; just as accurate.
    assert _round_trip_error(lp, 1e-4, spline=True) < 1e-4
    # What is left is the sampling of x0 (linear between samples): second order in dt.
    assert _round_trip_error(lp, 4e-4) / _round_trip_error(lp, 2e-4) > 3.5


def test_inverse_of_a_held_key_is_the_static_arm_position() -> None:
    lp = MSDParams().at(-40)
    t = np.arange(0.0, 0.2, 1e-3)
    x2 = np.full(t.size, 0.004)
    x0, x1 = inverse_trajectories(lp, t, x2, v2_mps=np.zeros_like(t), a2_mps2=np.zeros_like(t))
    x1_static = 0.004 * static_deformation_ratio(lp)
    np.testing.assert_allclose(x1, x1_static, rtol=1e-9)
    x0_static = ((lp.k0_npm + lp.k1_npm) * x1_static - lp.k1_npm * 0.004) / lp.k0_npm
    np.testing.assert_allclose(x0, x0_static, rtol=1e-9)


def test_inverse_needs_dampers() -> None:
    lp = MSDParams(c1_nspm=0.0).at(-60)
    with pytest.raises(ValueError, match="c1"):
        inverse_state_space(lp)


def test_params_law_table_and_overrides() -> None:
    p = MSDParams()
    assert p.k1_npm(-60) == pytest.approx(146.81)
    assert p.k1_npm(60) == pytest.approx(146.81)  # only |p| matters
    np.testing.assert_allclose(p.k1_npm(np.array([0.0, -80.0])), [75.41, 170.61])
    lp = p.at(-20)
    assert lp.k0_npm == lp.k1_npm == pytest.approx(75.41 + 23.8)
    assert lp.c0_nspm == lp.c1_nspm == 0.5 and lp.k2_npm == 300.0
    custom = p.replace(k0_npm=500.0, c0_nspm=2.0)
    assert custom.at(-20).k0_npm == 500.0 and custom.at(-20).c0_nspm == 2.0
    assert custom.at(-20).k1_npm == lp.k1_npm

    tabled = MSDParams(k1_table=((-40.0, 100.0), (-80.0, 180.0)))
    assert tabled.k1_npm(-40) == pytest.approx(100.0)
    assert tabled.k1_npm(-60) == pytest.approx(140.0)  # linear between levels
    assert tabled.k1_npm(-20) == pytest.approx(75.41 + 1.19 * 20)  # law outside
    assert tabled.k1_table == ((40.0, 100.0), (80.0, 180.0))


def test_params_dict_round_trip_and_validation() -> None:
    p = MSDParams(k2_npm=150.6, k0_npm=200.0, k1_table=((60.0, 150.0),))
    data = p.to_dict()
    assert data["k1_table"] == [[60.0, 150.0]]
    assert MSDParams.from_dict(data) == p
    with pytest.raises(ValueError, match="k3_npm"):
        MSDParams.from_dict({"k3_npm": 1.0})
    with pytest.raises(ValueError, match="m1_kg"):
        MSDParams(m1_kg=0.0)
    with pytest.raises(ValueError, match="k1_table"):
        MSDParams(k1_table=((60.0, -1.0),))


def test_static_deformation_ratio_from_simulation() -> None:
    lp = MSDParams().at(-60)
    t = np.arange(0.0, 3.0, 1e-3)
    x0 = np.interp(t, [0.0, 0.5, 3.0], [0.0, 0.02, 0.02])
    x1, x2 = simulate_linear(lp, t, x0)
    r = deformation_ratio(x1[-1], x1[0], x2[-1], x2[0])
    assert float(r) == pytest.approx(static_deformation_ratio(lp), rel=1e-6)
    assert static_deformation_ratio(lp) == pytest.approx((146.81 + 300.0) / 146.81)
    assert np.isnan(deformation_ratio(1.0, 0.0, 0.5, 0.5))


def test_error_rate() -> None:
    np.testing.assert_allclose(error_rate([2.2, 1.8], 2.0), [0.1, 0.1])
    assert float(error_rate(3.0, 3.0)) == 0.0
    assert math.isclose(float(error_rate(1.0, 4.0)), 0.75)
