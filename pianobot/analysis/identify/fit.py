"""Grey-box identification of the keystroke model from trajectories (output-error least squares).

The measured arm trace x0 drives the physical keystroke model (`identify_forward`: the fingertip
hangs from the arm on k0, c0 while it approaches the key from `distance_m` above, and the study's
2-DoF coupling acts from the instant it touches); the simulated fingertip x1 and key x2 are
compared with the measured ones at every frame of every keystroke until the fingertip lifts off
the key (where the study's bilateral coupling stops describing a real finger), and
`scipy.optimize.least_squares` (robust soft-L1 loss, `identify_problem`) adjusts

    k1 per vacuum level, c1, k2, c2     and, with coupling="free", k0 and c0
    (coupling="tied" keeps the study's k0 = k1, c0 = c1; "auto" picks by BIC).

What is fixed, and why: with x0 as the input and x1, x2 as outputs, scaling every mass, spring
and damper by the same factor leaves the trajectories unchanged, so one mass scale cannot be
identified. Both masses are held at the prior model's values (published m1 = 70 g, m2 = 34.05 g);
the identified stiffnesses and dampings are therefore relative to those masses, and the
mass-normalised values (k/m, c/m) are reported as well. Parameters are fitted in log space, so
they stay positive and the Jacobian intervals are multiplicative.

Intervals: (1) from the Jacobian at the optimum, as the larger (per parameter) of two
covariances — a sandwich whose middle is the long-run covariance of each keystroke's score
series (residuals are correlated along a keystroke), and the propagation of the measured noise
levels, including noise on the arm trace that drives the model (errors in variables, which the
fit partly absorbs and the residuals therefore hide; pushed through the model as seeded noise
draws); per-keystroke rest offsets are profiled out. Over 60 seeded sweeps of the simulated
linear world these cover the truth in 95 % of cases (`benchmarks/bench_identify.py`; the key's
damping c2 in 88 %: the world's arm reverses instantly, and the 500 Hz arm log cuts that corner). (2) Optionally a percentile
bootstrap over keystrokes (refits on keystrokes drawn with replacement per vacuum level). The
reported 95 % interval is their union.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from pianobot.analysis.greybox.covariance import hac_covariance, larger_variances, noise_covariance
from pianobot.analysis.greybox.fitter import RESIDUAL_SCALE_M, Layout, Problem, k1_law, k1_name
from pianobot.analysis.greybox.forward import simulate_batch
from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.physics.msd import MSDParams

FloatArray = npt.NDArray[np.float64]
Coupling = Literal["tied", "free", "auto"]

Z95 = 1.959963984540054

__all__ = ["Coupling", "Estimate", "TrajectoryFit", "estimates_table", "identify_trajectories", "k1_name",
           "rms_x2_m", "simulate_batch", "split_holdout"]


@dataclass(frozen=True)
class Estimate:
    """One identified quantity with its 95 % intervals."""

    name: str
    value: float
    unit: str
    ci_jacobian: tuple[float, float]
    ci_bootstrap: tuple[float, float] | None = None

    @property
    def ci95(self) -> tuple[float, float]:
        """Union of the Jacobian and bootstrap intervals (the conservative choice)."""
        lo, hi = self.ci_jacobian
        if self.ci_bootstrap is not None:
            lo, hi = min(lo, self.ci_bootstrap[0]), max(hi, self.ci_bootstrap[1])
        return lo, hi

    def row(self) -> dict[str, Any]:
        lo, hi = self.ci95
        boot = self.ci_bootstrap or (math.nan, math.nan)
        return {
            "name": self.name, "value": self.value, "unit": self.unit, "ci95_lo": lo, "ci95_hi": hi,
            "jacobian_lo": self.ci_jacobian[0], "jacobian_hi": self.ci_jacobian[1],
            "bootstrap_lo": boot[0], "bootstrap_hi": boot[1],
        }


@dataclass(frozen=True)
class TrajectoryFit:
    """Result of `identify_trajectories`."""

    params: MSDParams  # the identified model (k1_table holds the per-level stiffness)
    estimates: tuple[Estimate, ...]
    coupling: Literal["tied", "free"]
    rms_m: float  # RMS of x1, x2 residuals over every sample
    n_keystrokes: int
    n_samples: int
    bic: float
    fixed: dict[str, float]

    def estimate(self, name: str) -> Estimate:
        for e in self.estimates:
            if e.name == name:
                return e
        raise KeyError(name)


def _derived(theta: FloatArray, layout: Layout, prior: MSDParams) -> dict[str, float]:
    """Every reported quantity as a function of theta (so bootstrap and delta method share it)."""
    v = np.exp(theta)
    nl = len(layout.levels_kpa)
    out = {name: float(x) for name, x in zip(layout.names, v, strict=True)}
    a, b = k1_law(np.asarray(layout.levels_kpa), v[:nl], prior)
    out["k1_a_npm"], out["k1_b_npm_per_kpa"] = a, b
    out["c1_over_m1_per_s"] = out["c1_nspm"] / prior.m1_kg
    out["c2_over_m2_per_s"] = out["c2_nspm"] / prior.m2_kg
    out["k2_over_m2_per_s2"] = out["k2_npm"] / prior.m2_kg
    return out


UNITS = {"c1_nspm": "N*s/m", "k2_npm": "N/m", "c2_nspm": "N*s/m", "k0_npm": "N/m",
         "c0_nspm": "N*s/m", "k1_a_npm": "N/m", "k1_b_npm_per_kpa": "N/m/kPa",
         "c1_over_m1_per_s": "1/s", "c2_over_m2_per_s": "1/s", "k2_over_m2_per_s2": "1/s^2"}


def _fit_once(batch: KeystrokeBatch, prior: MSDParams, free: bool, theta0: FloatArray | None) -> tuple[Problem, FloatArray]:
    problem = Problem(batch, Layout.of(batch, free), prior)
    start = problem.layout.initial(prior) if theta0 is None else theta0
    return problem, problem.fit(start)


def identify_trajectories(
    batch: KeystrokeBatch,
    *,
    prior: MSDParams | None = None,
    coupling: Coupling = "auto",
    bootstrap: int = 0,
    seed: int = 0,
) -> TrajectoryFit:
    """Fit the keystroke model to the batch (see the module docstring).

    Args:
        batch: keystrokes with arm input, gap at the start and measured fingertip/key trajectories.
        prior: starting values and the fixed masses (default: the published parameters).
        coupling: "tied" (k0 = k1, c0 = c1), "free", or "auto" (free only if BIC drops by > 10).
        bootstrap: number of bootstrap refits over keystrokes (0: Jacobian intervals only).
        seed: bootstrap and noise-draw random seed.
    """
    prior = prior or MSDParams()
    problem, theta = _fit_once(batch, prior, coupling == "free", None)
    bic = problem.bic(theta)
    if coupling == "auto":
        lp = problem.layout.params(theta, prior).at(-problem.layout.levels_kpa[0])
        start = np.r_[theta, np.log([lp.k0_npm, lp.c0_nspm])]
        p_free, th_free = _fit_once(batch, prior, True, start)
        bic_free = p_free.bic(th_free)
        if bic_free < bic - 10.0:
            problem, theta, bic = p_free, th_free, bic_free
    layout = problem.layout

    r = problem.residuals(theta)
    J = problem.jacobian(theta)
    # Two honest estimates of the same covariance under different assumptions; keep the
    # larger variance of each parameter: the residual-based HAC sandwich (right under model
    # error, blind to errors the fit absorbs) and the measurement-noise propagation (right when
    # the model is correct, including noise on the arm trace that drives it).
    hac = hac_covariance(problem.mask, J, r)
    noise = noise_covariance(problem.mask, J, problem.output_noise(theta), problem.input_noise_scores(theta, J, seed))
    cov = larger_variances(hac, noise)
    point = _derived(theta, layout, prior)
    jac_ci = _delta_intervals(theta, cov, layout, prior, point)
    boot_ci = _bootstrap_intervals(batch, theta, layout, prior, bootstrap, seed) if bootstrap > 0 else {}
    estimates = tuple(
        Estimate(n, point[n], UNITS.get(n, "N/m"), jac_ci[n], boot_ci.get(n)) for n in point
    )
    return TrajectoryFit(
        params=layout.params(theta, prior),
        estimates=estimates,
        coupling="free" if layout.free_coupling else "tied",
        rms_m=float(math.sqrt(float(r @ r) / r.size)) * RESIDUAL_SCALE_M,
        n_keystrokes=batch.n,
        n_samples=int(r.size),
        bic=bic,
        fixed={"m1_kg": prior.m1_kg, "m2_kg": prior.m2_kg},
    )


def _delta_intervals(theta: FloatArray, cov: FloatArray, layout: Layout, prior: MSDParams,
                     point: dict[str, float]) -> dict[str, tuple[float, float]]:
    """95 % intervals of every reported quantity from the covariance of theta (delta method)."""
    names = list(point)
    grads = np.zeros((len(names), theta.size))
    for j in range(theta.size):  # gradient of each derived quantity by finite differences
        d = np.zeros_like(theta)
        d[j] = 1e-6
        up = _derived(theta + d, layout, prior)
        grads[:, j] = [(up[n] - point[n]) / 1e-6 for n in names]
    out: dict[str, tuple[float, float]] = {}
    for i, n in enumerate(names):
        if n in layout.names:  # log-parameterised: multiplicative interval
            sd = math.sqrt(max(cov[layout.names.index(n), layout.names.index(n)], 0.0))
            half = Z95 * sd
            # An unidentified parameter (flat cost) gets an unbounded interval, not an overflow.
            out[n] = (point[n] * math.exp(-half), point[n] * math.exp(half)) if half < 50 else (0.0, math.inf)
        else:
            sd = math.sqrt(max(float(grads[i] @ cov @ grads[i]), 0.0))
            out[n] = (point[n] - Z95 * sd, point[n] + Z95 * sd)
    return out


def _bootstrap_intervals(batch: KeystrokeBatch, theta: FloatArray, layout: Layout, prior: MSDParams,
                         draws: int, seed: int) -> dict[str, tuple[float, float]]:
    """Percentile intervals from refits on keystrokes drawn with replacement within each level."""
    if batch.n < 3:
        return {}
    rng = np.random.default_rng(seed)
    level = np.abs(batch.vacuum_kpa)
    found = []
    for _ in range(draws):
        # Drawn per level: a draw must contain every vacuum level, or its k1 is undefined.
        idx = np.concatenate([rng.choice(np.flatnonzero(level == p), int((level == p).sum()))
                              for p in layout.levels_kpa])
        found.append(_derived(Problem(batch.subset(idx), layout, prior).fit(theta), layout, prior))
    return {n: (float(np.percentile([d[n] for d in found], 2.5)), float(np.percentile([d[n] for d in found], 97.5)))
            for n in found[0]}


def rms_x2_m(batch: KeystrokeBatch, params: MSDParams) -> float:
    """RMS error of the simulated key trajectory x2 over the batch (for held-out comparisons)."""
    _, x2 = simulate_batch(batch, params)
    err = x2 - batch.x2_m
    return float(np.sqrt(np.nanmean(err**2)))


def split_holdout(batch: KeystrokeBatch, every: int = 3) -> tuple[KeystrokeBatch, KeystrokeBatch]:
    """Deterministic split: every `every`-th keystroke (per vacuum level) is held out."""
    held: list[int] = []
    for p in sorted(set(np.abs(batch.vacuum_kpa).tolist())):
        idx = np.flatnonzero(np.abs(batch.vacuum_kpa) == p)
        held.extend(idx[every - 1 :: every].tolist())
    test = np.array(sorted(held), dtype=np.intp)
    train = np.setdiff1d(np.arange(batch.n), test)
    if train.size == 0 or test.size == 0:
        return batch, batch
    return batch.subset(train), batch.subset(test)


def estimates_table(estimates: Sequence[Estimate]) -> list[dict[str, Any]]:
    """Rows for printing or JSON."""
    return [e.row() for e in estimates]
