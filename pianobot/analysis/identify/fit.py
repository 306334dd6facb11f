"""Grey-box identification of the keystroke model from trajectories: the base configuration of
the shared fitter (`greybox.fitter.GreyBoxFit`).

The measured arm trace x0 drives the physical keystroke model (`greybox.forward.MeasuredArm`:
the fingertip hangs from the arm on k0, c0 while it approaches the key from `distance_m` above,
and the study's 2-DoF coupling acts from the instant it touches); the simulated fingertip x1 and
key x2 are compared with the measured ones at every frame of every keystroke until the fingertip
lifts off the key (where the study's bilateral coupling stops describing a real finger), and the
fitter adjusts (`greybox.layout.base_layout`)

    k1 per vacuum level, c1, k2, c2     and, with coupling="free", k0/k1, c0/c1 and the fingertip mass m1
    (coupling="tied" keeps the study's k0 = k1, c0 = c1 and m1; "auto" picks by the
    information criterion, `greybox.criterion`).

What is fixed, and why: with x0 as the input and x1, x2 as outputs, scaling every mass, spring
and damper by the same factor leaves the trajectories unchanged, so one mass scale cannot be
identified: the key's mass m2 is held at the prior model's value (published 34.05 g), and the
identified stiffnesses and dampings are relative to it; the mass-normalised values (k/m, c/m)
are reported as well. Parameters are fitted in log space, so they stay positive and the
Jacobian intervals are multiplicative; a parameter that ends on a bound is flagged.

Intervals: (1) from the Jacobian at the optimum, as the larger (per parameter) of two
covariances — a sandwich whose middle is the long-run covariance of each keystroke's score
series (residuals are correlated along a keystroke), and the propagation of the measured noise
levels, including noise on the arm trace that drives the model (errors in variables, which the
fit partly absorbs and the residuals therefore hide; pushed through the model as seeded noise
draws); per-keystroke rest offsets are profiled out. Over 60 seeded sweeps of the simulated
linear world these cover the truth in 95 % of cases (`benchmarks/bench_identify.py`). (2)
Optionally a percentile bootstrap over keystrokes (refits on keystrokes drawn with replacement
per vacuum level). The reported 95 % interval is their union.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from pianobot.analysis.greybox.covariance import Z95
from pianobot.analysis.greybox.criterion import Criterion
from pianobot.analysis.greybox.fitter import GreyBoxFit
from pianobot.analysis.greybox.forward import MeasuredArm, simulate_batch
from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.analysis.greybox.layout import Layout, base_layout, gauge_kpa, k1_law, k1_name
from pianobot.analysis.greybox.pieces import Mapper, serial_map
from pianobot.analysis.greybox.split import split_holdout
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.msd import MSDParams
from pianobot.progress import NO_PROGRESS, Progress

FloatArray = npt.NDArray[np.float64]
Coupling = Literal["tied", "free", "auto"]

#: "auto" coupling frees k0, c0 and m1 only if the information criterion drops by more than this.
COUPLING_MARGIN = 10.0

__all__ = ["Coupling", "Estimate", "TrajectoryFit", "estimates_table", "fit_base", "identify_trajectories",
           "k1_name", "rms_x2_m", "simulate_batch", "split_holdout"]


@dataclass(frozen=True)
class Estimate:
    """One identified quantity with its 95 % intervals."""

    name: str
    value: float
    unit: str
    ci_jacobian: tuple[float, float]
    ci_bootstrap: tuple[float, float] | None = None
    on_bound: bool = False  # the fit ended on this parameter's bound: the data do not pin it

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
            "bootstrap_lo": boot[0], "bootstrap_hi": boot[1], "on_bound": self.on_bound,
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
    ic: float  # information criterion (`greybox.criterion`), on this fit's own residuals
    fixed: dict[str, float]
    on_bounds: tuple[str, ...] = ()

    def estimate(self, name: str) -> Estimate:
        for e in self.estimates:
            if e.name == name:
                return e
        raise KeyError(name)


UNITS = {"c1_nspm": "N*s/m", "k2_npm": "N/m", "c2_nspm": "N*s/m", "k0_over_k1": "1", "c0_over_c1": "1", "m1_kg": "kg",
         "c0_nspm": "N*s/m", "k1_a_npm": "N/m", "k1_b_npm_per_kpa": "N/m/kPa",
         "c1_over_m1_per_s": "1/s", "c2_over_m2_per_s": "1/s", "k2_over_m2_per_s2": "1/s^2"}


def _derived(theta: FloatArray, layout: Layout) -> dict[str, float]:
    """Every reported quantity as a function of theta (so bootstrap and delta method share it)."""
    out = layout.values(theta)
    msd = layout.prior.msd
    levels = np.asarray(layout.levels_kpa)
    a, b = k1_law(levels, np.array([out[k1_name(p)] for p in layout.levels_kpa]), msd)
    out["k1_a_npm"], out["k1_b_npm_per_kpa"] = a, b
    if "k0_over_k1" in out:  # the arm-fingertip coupling at each level, for reading
        for p in layout.levels_kpa:
            out[f"k0_npm@{gauge_kpa(p):g}kPa"] = out["k0_over_k1"] * out[k1_name(p)]
        out["c0_nspm"] = out["c0_over_c1"] * out["c1_nspm"]
    m1 = out.get("m1_kg", msd.m1_kg)
    out["c1_over_m1_per_s"] = out["c1_nspm"] / m1
    out["c2_over_m2_per_s"] = out["c2_nspm"] / msd.m2_kg
    out["k2_over_m2_per_s2"] = out["k2_npm"] / msd.m2_kg
    return out


def _fit_layout(batch: KeystrokeBatch, prior: KeystrokeModel, free: bool, theta0: FloatArray | None = None,
             drive: MeasuredArm | None = None) -> GreyBoxFit:
    """The base model's fit on a batch (the prior's effects stay on, at their values)."""
    layout = base_layout(prior, batch.levels_kpa, free_coupling=free)
    return GreyBoxFit(drive or MeasuredArm.of(batch), layout).fit(theta0)


def _criterion(fit: GreyBoxFit) -> Criterion:
    res = fit.residuals_
    return Criterion.of(res.values, res.keystroke, res.frame, fit.noise(res))


def fit_base(batch: KeystrokeBatch, prior: KeystrokeModel, coupling: Coupling = "auto",
             mapper: Mapper = serial_map) -> GreyBoxFit:
    """Identification's base fit: tied coupling, or free (k0, c0, m1) when asked or when the
    information criterion, on the tied fit's effective sample size, prefers it by > 10.

    The free fit starts from the tied fit's values and from the prior, and the better of the two
    is kept. A tied model is structurally wrong for a finger whose body and pad differ, and where
    the take also holds an effect the model lacks (a let-off, a stop) its fit can end far from
    any physical finger (seen: a 4 N/m pad, a 12 N/m key). A free fit started there may follow it
    into a quasi-static corner (a massless, heavily damped finger that tracks the arm) whose
    error is close to, but above, that of the physical optimum the prior's start reaches. The two
    free fits are independent pieces (`mapper`)."""
    drive = MeasuredArm.of(batch)
    fit = _fit_layout(batch, prior, coupling == "free", drive=drive)
    if coupling == "auto":
        free_layout = base_layout(prior, batch.levels_kpa, free_coupling=True)
        criterion = _criterion(fit)

        def ic(candidate: GreyBoxFit) -> float:
            return criterion.value(candidate.channels_, len(candidate.theta_))

        def free_fit(start: FloatArray | None) -> GreyBoxFit:
            return GreyBoxFit(drive, free_layout).fit(start)

        free = min(mapper(free_fit, [free_layout.internal(fit.params_), None]), key=ic)
        if ic(free) < ic(fit) - COUPLING_MARGIN:
            fit = free
    return fit


def identify_trajectories(
    batch: KeystrokeBatch,
    *,
    prior: MSDParams | None = None,
    coupling: Coupling = "auto",
    bootstrap: int = 0,
    seed: int = 0,
    progress: Progress = NO_PROGRESS,
    mapper: Mapper = serial_map,
) -> TrajectoryFit:
    """Fit the keystroke model to the batch (see the module docstring).

    Args:
        batch: keystrokes with arm input, gap at the start and measured fingertip/key trajectories.
        prior: starting values and the fixed key mass (default: the published parameters).
        coupling: "tied" (k0 = k1, c0 = c1, published m1), "free", or "auto" (free only if the
            information criterion drops by > 10).
        bootstrap: number of bootstrap refits over keystrokes (0: Jacobian intervals only).
        seed: bootstrap and noise-draw random seed.
        mapper: how the independent bootstrap refits are run (default: one after another).
    """
    prior_model = KeystrokeModel(msd=prior or MSDParams())
    fit = fit_base(batch, prior_model, coupling, mapper)
    layout = fit.layout
    theta = fit.theta_
    cov = fit.covariance(seed)
    point = _derived(theta, layout)
    jac_ci = _delta_intervals(theta, cov, layout, point)
    boot_ci = _bootstrap_intervals(batch, theta, layout, bootstrap, seed, progress, mapper) if bootstrap > 0 else {}
    on_bounds = set(fit.on_bounds_)
    estimates = tuple(Estimate(n, point[n], UNITS.get(n, "N/m"), jac_ci[n], boot_ci.get(n), n in on_bounds)
                      for n in point)
    fixed = {"m2_kg": prior_model.msd.m2_kg}
    if not layout.free_coupling:
        fixed = {"m1_kg": prior_model.msd.m1_kg, **fixed}
    return TrajectoryFit(
        params=fit.model_.msd,
        estimates=estimates,
        coupling="free" if layout.free_coupling else "tied",
        rms_m=fit.rms_m_,
        n_keystrokes=batch.n,
        n_samples=fit.n_samples_,
        ic=_criterion(fit).value(fit.channels_, len(theta)),
        fixed=fixed,
        on_bounds=fit.on_bounds_,
    )


#: Derived quantities that may take either sign: the slope of k1 over vacuum.
SIGNED = frozenset({"k1_b_npm_per_kpa"})


def _delta_intervals(theta: FloatArray, cov: FloatArray, layout: Layout,
                     point: dict[str, float]) -> dict[str, tuple[float, float]]:
    """95 % intervals of every reported quantity from the covariance of theta (delta method)."""
    names = list(point)
    grads = np.zeros((len(names), theta.size))
    for j in range(theta.size):  # gradient of each derived quantity by finite differences
        d = np.zeros_like(theta)
        d[j] = 1e-6
        up = _derived(theta + d, layout)
        grads[:, j] = [(up[n] - point[n]) / 1e-6 for n in names]
    out: dict[str, tuple[float, float]] = {}
    free = layout.names
    for i, n in enumerate(names):
        if n in free:  # log-parameterised: multiplicative interval
            sd = math.sqrt(max(cov[free.index(n), free.index(n)], 0.0))
            half = Z95 * sd
            # An unidentified parameter (flat cost) gets an unbounded interval, not an overflow.
            out[n] = (point[n] * math.exp(-half), point[n] * math.exp(half)) if half < 50 else (0.0, math.inf)
        else:
            sd = math.sqrt(max(float(grads[i] @ cov @ grads[i]), 0.0))
            if point[n] > 0 and n not in SIGNED:
                # A stiffness, damping, mass or a ratio of them (c2/m2) derived from
                # log-parameterised ones: multiplicative too (the delta method on its logarithm),
                # so its interval never crosses zero (c2/m2 read [-676, 2203] 1/s).
                half = Z95 * sd / point[n]
                out[n] = (point[n] * math.exp(-half), point[n] * math.exp(half)) if half < 50 else (0.0, math.inf)
            else:  # a slope (k1's change per kPa) may take either sign
                out[n] = (point[n] - Z95 * sd, point[n] + Z95 * sd)
    return out


def _bootstrap_intervals(
    batch: KeystrokeBatch, theta: FloatArray, layout: Layout, draws: int, seed: int, progress: Progress,
    mapper: Mapper,
) -> dict[str, tuple[float, float]]:
    """Percentile intervals from refits on keystrokes drawn with replacement within each level."""
    if batch.n < 3:
        return {}
    level = np.abs(batch.vacuum_kpa)
    rng = np.random.default_rng(seed)
    # Draws are made up front, so serial and parallel runs refit the same keystroke sets.
    picks = [np.concatenate([rng.choice(np.flatnonzero(level == p), int((level == p).sum()))
                             for p in layout.levels_kpa]) for _ in range(draws)]

    def refit(i: int) -> dict[str, float]:
        sub = batch.subset(picks[i])
        return _derived(GreyBoxFit(MeasuredArm.of(sub), layout).fit(theta).theta_, layout)

    found: list[dict[str, float]] = []
    with progress.task("bootstrap refits", total=draws) as task:
        for i, out in enumerate(mapper(refit, range(draws))):
            found.append(out)
            task.advance(note=f"keystroke set {i + 1} of {draws}")
    return {n: (float(np.percentile([d[n] for d in found], 2.5)), float(np.percentile([d[n] for d in found], 97.5)))
            for n in found[0]}


def rms_x2_m(batch: KeystrokeBatch, params: MSDParams | KeystrokeModel) -> float:
    """RMS error of the simulated key trajectory x2 over the batch (for held-out comparisons),
    with each keystroke's rest offset profiled out as in the fit."""
    _, x2 = simulate_batch(batch, params)
    err = x2 - batch.x2_m
    err = err - np.nanmean(err, axis=1, keepdims=True)
    return float(np.sqrt(np.nanmean(err**2)))


def estimates_table(estimates: Sequence[Estimate]) -> list[dict[str, Any]]:
    """Rows for printing or JSON."""
    return [e.row() for e in estimates]
