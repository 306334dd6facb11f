"""The long-run (HAC) covariance: its matrix-product sums are the sandwich's definition."""

from __future__ import annotations

import numpy as np

from pianobot.analysis.greybox.covariance import _score_window, hac_covariance, unseen_unknown


def test_the_hac_covariance_is_the_newey_west_sandwich_per_series() -> None:
    rng = np.random.default_rng(5)
    n, T, p = 3, 60, 4
    # Residuals that ring (correlated along each series), as a key's do.
    e = rng.normal(size=(n, T + 10))
    r = np.stack([np.convolve(row, np.ones(10) / 10, mode="valid")[:T] for row in e]).ravel()
    J = rng.normal(size=(n * T, p))
    series, position = np.repeat(np.arange(n), T), np.tile(np.arange(T), n)
    cov = hac_covariance(J, r, series, position)

    g = (J * r[:, None]).reshape(n, T, p)
    lag = _score_window(g)
    assert lag > 1  # the ringing is seen
    meat = sum(np.outer(g[k, t], g[k, t]) for k in range(n) for t in range(T))
    for ell in range(1, lag + 1):
        gamma = sum(np.outer(g[k, t], g[k, t - ell]) for k in range(n) for t in range(ell, T))
        meat += (1.0 - ell / (lag + 1.0)) * (gamma + gamma.T)
    bread = np.linalg.inv(J.T @ J)
    expected = bread @ meat @ bread * (r.size / (r.size - p))
    np.testing.assert_allclose(cov, 0.5 * (expected + expected.T), rtol=1e-10)


def test_a_parameter_no_residual_depends_on_is_unknown_not_exact() -> None:
    rng = np.random.default_rng(2)
    J = rng.normal(size=(200, 3))
    J[:, 1] = 0.0  # e.g. a pull-off force the pad never reaches
    r = rng.normal(size=200)
    series, position = np.zeros(200, dtype=np.intp), np.arange(200)
    raw = hac_covariance(J, r, series, position)
    assert raw[1, 1] == 0.0  # the pseudo-inverse's answer: known exactly
    cov = unseen_unknown(raw, J)
    assert np.isinf(cov[1, 1]) and not np.any(cov[1, [0, 2]]) and not np.any(cov[[0, 2], 1])
    np.testing.assert_array_equal(cov[np.ix_([0, 2], [0, 2])], raw[np.ix_([0, 2], [0, 2])])
