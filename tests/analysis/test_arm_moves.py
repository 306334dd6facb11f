"""The batched trapezoid fit behind `arm_acceleration`: exact derivatives, and fits at least as
good as one `scipy.optimize.least_squares` per move (what it replaced), on moves made by
integrating an acceleration profile step by step (no trapezoid formula involved)."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import least_squares

from pianobot.analysis.discover.arm_moves import DownMoves, fit_moves, trapezoid

FloatArray = npt.NDArray[np.float64]
DT = 1e-3


def integrated_move(d: float, v: float, a: float, t0: float, span_s: float) -> tuple[FloatArray, FloatArray]:
    """A moveL from rest by stepping its acceleration (+a until v, cruise, −a to stop at d)."""
    t = np.arange(-0.1, span_s, DT)
    x, speed, out = 0.0, 0.0, np.zeros_like(t)
    for i, now in enumerate(t):
        if now >= t0 and x < d:
            stop_dist = speed * speed / (2.0 * a)
            acc = -a if d - x <= stop_dist else (a if speed < v else 0.0)
            speed = max(min(speed + acc * DT, v), 0.0)
            x = min(x + speed * DT, d)
        out[i] = x
    return t, out


def one_by_one(t: FloatArray, x: FloatArray, p0: FloatArray, lo: FloatArray, hi: FloatArray, a: float) -> float:
    """The replaced fit: one bounded least_squares per move (2-point differences)."""
    params = np.asarray(p0)

    def residual(p: FloatArray) -> FloatArray:
        return trapezoid(t[None, :], p[None, :], a)[0][0] - x

    return float(np.sum(least_squares(residual, params, bounds=(lo, hi), x_scale="jac", max_nfev=200).fun ** 2))


@pytest.mark.parametrize("a", [0.2, 1.0, 8.0, math.inf])
def test_the_derivatives_are_the_finite_differences_away_from_the_corners(a: float) -> None:
    t = np.linspace(-0.2, 1.5, 3000)[None, :].repeat(3, axis=0)
    params = np.array([[0.03, 0.06, 0.05], [0.004, 0.2, 0.0], [0.05, 0.03, 0.2]])  # [1]: a triangle
    s, jac = trapezoid(t, params, a)
    h = 1e-8
    for j in range(3):
        shifted = params.copy()
        shifted[:, j] += h
        numeric = (trapezoid(t, shifted, a)[0] - s) / h
        close = np.isclose(numeric, jac[..., j], rtol=1e-4, atol=1e-5)
        assert close.mean() > 0.995, (j, close.mean())  # only samples at a corner may differ


@settings(max_examples=12, deadline=None)
@given(st.lists(st.tuples(st.floats(0.01, 0.05), st.floats(0.01, 0.12), st.floats(0.0, 0.3)),
                min_size=2, max_size=5),
       st.sampled_from([0.3, 1.0, 3.0]), st.sampled_from([0.25, 1.0, 4.0, math.inf]))
def test_each_move_fits_at_least_as_well_as_alone(
    truths: list[tuple[float, float, float]], a_true: float, a_fit: float,
) -> None:
    rng = np.random.default_rng(len(truths))
    moves = []
    for d, v, t0 in truths:
        t, x = integrated_move(d, v, a_true, t0, t0 + d / v + v / a_true + 0.1)
        moves.append((t, x + rng.normal(0.0, 2e-5, x.size)))
    padded = DownMoves.of(moves)
    fit = fit_moves(padded, a_fit)
    alone = [one_by_one(t, x, padded.p0[k], padded.lo[k], padded.hi[k], a_fit) for k, (t, x) in enumerate(moves)]
    together = [float(np.sum(r**2)) for r in padded.residuals(fit.residual)]
    for mine, theirs in zip(together, alone, strict=True):
        assert mine <= theirs * (1 + 1e-3) + 1e-12
    assert fit.rss == pytest.approx(sum(together))


def test_the_true_move_is_found_at_the_true_acceleration() -> None:
    rng = np.random.default_rng(4)
    truths = [(0.03, 0.05, 0.1), (0.02, 0.09, 0.0), (0.045, 0.02, 0.25)]
    moves = []
    for d, v, t0 in truths:
        t, x = integrated_move(d, v, 1.0, t0, t0 + d / v + 1.0)
        moves.append((t, x + rng.normal(0.0, 1e-5, x.size)))
    fit = fit_moves(DownMoves.of(moves), 1.0)
    np.testing.assert_allclose(fit.params[:, 0], [d for d, _, _ in truths], rtol=2e-3)
    np.testing.assert_allclose(fit.params[:, 1], [v for _, v, _ in truths], rtol=2e-2)
    np.testing.assert_allclose(fit.starts, [t0 for _, _, t0 in truths], atol=3e-3)
    # A ramp or a much gentler acceleration explains the same moves worse.
    assert fit_moves(DownMoves.of(moves), math.inf).rss > 5 * fit.rss
    assert fit_moves(DownMoves.of(moves), 0.2).rss > 5 * fit.rss
