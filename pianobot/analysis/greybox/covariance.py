"""Covariances of identified parameters when residuals are not independent white noise.

Used by the grey-box fitter: keystroke residuals are correlated in time (the key rings, the arm
trace is noisy and drives the model), so s²(JᵀJ)⁻¹ is too narrow. Two estimates:

- `hac_covariance`: sandwich with a long-run (Newey–West) middle per keystroke, window from the
  scores' own autocorrelation — honest under model error;
- `noise_covariance`: linearised propagation of the measured noise levels through the model,
  including noise on its input (simulated draws) — honest when the model is right, and the only
  one that sees the part of the input noise the fit absorbs.

`larger_variances` combines them (per parameter the larger variance).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

#: The standard normal quantile of 97.5 %: a 95 % interval is the estimate ± Z95 standard errors.
Z95 = 1.959963984540054


def hac_covariance(J: FloatArray, r: FloatArray, series: npt.NDArray[np.intp], position: npt.NDArray[np.intp],
                   n_offsets: int = 0) -> FloatArray:
    """Covariance of the parameters, robust to residuals correlated along each keystroke.

    The residuals of one keystroke are not independent: noise on the measured arm trace is
    filtered by the model into slow, smooth errors on x1 and x2 (and any model error is smooth
    too), so neighbouring samples carry nearly the same information. Counting them as
    independent (s²(JᵀJ)⁻¹) makes intervals too narrow. Here the score g_t = Σ J_t r_t of each
    series (a keystroke's trajectory; x1 and x2 at one instant share a slot: they share the
    input noise; each MIDI residual is a series of its own) is treated as a time series and its
    long-run covariance is estimated with Bartlett (Newey–West) weights up to a lag chosen from
    the scores' own autocorrelation (`_score_window`); series are independent of each other.
    The sandwich (JᵀJ)⁻¹ · meat · (JᵀJ)⁻¹ then equals s²(JᵀJ)⁻¹ for white residuals and widens
    by the effective-sample-size factor when they are correlated, without needing many
    keystrokes (a keystroke-cluster sandwich needs dozens of clusters per parameter).

    Args:
        series, position: per residual (row of J), its series and its time index in it.
        n_offsets: nuisance parameters profiled out of the residuals (rest offsets).
    """
    p = J.shape[1]
    if r.size == 0:
        return np.zeros((p, p))
    _, s_idx = np.unique(series, return_inverse=True)
    n, T = int(s_idx.max()) + 1, int(position.max()) + 1
    g = np.zeros((n, T, p))
    np.add.at(g, (s_idx.ravel(), position), J * r[:, None])
    lag = _score_window(g)
    # Sums over times as one matrix product per keystroke, then over keystrokes (20x faster than
    # einsum's loop, which took 5 % of a discovery on a take; equal to 1e-15 relative).
    meat = np.matmul(g.transpose(0, 2, 1), g).sum(axis=0)
    for ell in range(1, lag + 1):
        gamma = np.matmul(g[:, ell:].transpose(0, 2, 1), g[:, :-ell]).sum(axis=0)
        meat += (1.0 - ell / (lag + 1.0)) * (gamma + gamma.T)
    bread = np.linalg.pinv(J.T @ J)
    dof = max(r.size - p - n_offsets, 1)
    cov = bread @ meat @ bread * (r.size / dof)  # small-sample correction, as for s²
    return np.asarray(0.5 * (cov + cov.T), dtype=np.float64)


def unseen_unknown(cov: FloatArray, J: FloatArray) -> FloatArray:
    """`cov` with every parameter no residual depends on (an all-zero Jacobian column, e.g. a
    pad that never pulls hard enough to let go) unknown: infinite variance, no covariance. The
    pseudo-inverse in the sandwich gives such a parameter zero variance, an interval of one
    point, which would pass any test that its interval excludes a value."""
    unseen = ~np.any(J != 0.0, axis=0)
    if not unseen.any():
        return cov
    out = cov.copy()
    out[unseen, :] = 0.0
    out[:, unseen] = 0.0
    out[unseen, unseen] = np.inf
    return out


def larger_variances(a: FloatArray, b: FloatArray) -> FloatArray:
    """Per-parameter larger variance of two covariances, with the correlations of the one that
    is larger overall (so the result stays a valid, positive semi-definite covariance)."""
    va, vb = np.clip(np.diag(a), 0.0, None), np.clip(np.diag(b), 0.0, None)
    base = a if float(np.sum(va / np.maximum(vb, 1e-300))) >= va.size else b
    sd_base = np.sqrt(np.clip(np.diag(base), 1e-300, None))
    corr = base / np.outer(sd_base, sd_base)
    sd = np.sqrt(np.maximum(va, vb))
    return np.asarray(corr * np.outer(sd, sd), dtype=np.float64)


def noise_covariance(J: FloatArray, sigma: FloatArray, input_scores: FloatArray) -> FloatArray:
    """Covariance of the parameters propagated from white measurement noise (linearised).

    θ̂ − θ ≈ −(JᵀJ)⁻¹ Jᵀ (G e_in − e_out): output noise e_out enters directly, noise e_in on the
    measured arm trace enters through the model G itself. G e_in rings like the key, i.e. much
    like a change of the key's parameters, so the fit absorbs part of it and the residuals no
    longer show it (an errors-in-variables effect the residual-based sandwich cannot see).

    Args:
        J: Jacobian of the residuals with respect to the parameters.
        sigma: white noise σ of each residual, in the residuals' unit.
        input_scores: (draws, p) rows Jᵀ G e_in for simulated draws of the input noise e_in
            (the model is piecewise: before and after touch, so G is simulated, not convolved);
            no rows: no input noise.
    """
    meat = (J * (sigma**2)[:, None]).T @ J
    if input_scores.shape[0] > 0:
        meat += input_scores.T @ input_scores / input_scores.shape[0]
    bread = np.linalg.pinv(J.T @ J)
    cov = bread @ meat @ bread
    return np.asarray(0.5 * (cov + cov.T), dtype=np.float64)


def _score_window(g: FloatArray, c: float = 5.0) -> int:
    """Truncation lag for the long-run covariance of the per-keystroke score series g (n, T, p).

    The key is a lightly damped resonator: arm-trace noise reaches x2 as a ringing error whose
    correlation oscillates and decays over tens of samples, which a lag-1 (AR(1)) rule misses.
    Instead the window follows the data: for each parameter's score, the integrated
    autocorrelation time τ(W) = 1 + 2 Σ_{l≤W} ρ(l) is accumulated until W ≥ c·τ(W) (Sokal's
    automatic window); the widest window over the parameters is used, at most T/2.
    """
    n, T, p = g.shape
    var = np.einsum("ktp,ktp->p", g, g)
    widest = 1
    for j in range(p):
        if var[j] <= 0:
            continue
        tau = 1.0
        for ell in range(1, T // 2):
            tau += 2.0 * float(np.sum(g[:, ell:, j] * g[:, :-ell, j])) / var[j]
            if ell >= c * max(tau, 1.0):
                widest = max(widest, ell)
                break
        else:
            widest = T // 2
    return int(min(max(widest, 1), max(T // 2, 1)))
