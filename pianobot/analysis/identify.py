"""Grey-box identification of the keystroke model from trajectories (output-error least squares).

The measured arm trace x0 drives the 2-DoF model (`pianobot.physics.msd`); the simulated
fingertip x1 and key x2 are compared with the measured ones over every keystroke at once, and
`scipy.optimize.least_squares` (robust soft-L1 loss) adjusts

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
fit partly absorbs and the residuals therefore hide); per-keystroke rest offsets are profiled
out. Over 20 seeded synthetic repetitions these cover the truth in ≥ 95 % of cases
(`benchmarks/bench_identify.py`). (2) Optionally a percentile bootstrap over keystrokes
(refits on keystrokes drawn with replacement per vacuum level). The reported 95 % interval is
their union.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from pianobot.analysis.identify_covariance import hac_covariance, larger_variances, noise_covariance
from pianobot.analysis.keystroke_batch import KeystrokeBatch
from pianobot.physics.msd import MSDParams, StateSpace, lsim_uniform, state_space

FloatArray = npt.NDArray[np.float64]
Coupling = Literal["tied", "free", "auto"]

#: Residuals are in millimetres so the robust loss scale reads naturally (0.05 mm ≈ mocap noise ×10).
RESIDUAL_SCALE_M = 1.0e-3
Z95 = 1.959963984540054


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
class _Layout:
    """Which entries of the log-parameter vector mean what."""

    levels_kpa: tuple[float, ...]
    free_coupling: bool

    @property
    def names(self) -> list[str]:
        names = [k1_name(p) for p in self.levels_kpa] + ["c1_nspm", "k2_npm", "c2_nspm"]
        return names + (["k0_npm", "c0_nspm"] if self.free_coupling else [])

    def initial(self, prior: MSDParams) -> FloatArray:
        values = [prior.k1_npm(p) for p in self.levels_kpa]
        values += [prior.c1_nspm, prior.k2_npm, prior.c2_nspm]
        if self.free_coupling:
            lp = prior.at(self.levels_kpa[len(self.levels_kpa) // 2])
            values += [lp.k0_npm, lp.c0_nspm]
        return np.log(np.asarray(values, dtype=np.float64))


def k1_name(vacuum_kpa: float) -> str:
    """Name of the per-level stiffness, e.g. `k1_npm@-40kPa`."""
    return f"k1_npm@{-abs(vacuum_kpa):g}kPa"


def _systems(theta: FloatArray, layout: _Layout, prior: MSDParams, level_idx: npt.NDArray[np.intp]) -> StateSpace:
    """Batched state space (one system per keystroke) for log-parameters theta."""
    v = np.exp(theta)
    nl = len(layout.levels_kpa)
    c1, k2, c2 = v[nl], v[nl + 1], v[nl + 2]
    A, B = [], []
    for j in range(nl):
        k1 = v[j]
        k0, c0 = (v[nl + 3], v[nl + 4]) if layout.free_coupling else (k1, c1)
        lp = prior.replace(k0_npm=k0, c0_nspm=c0, c1_nspm=c1, k2_npm=k2, c2_nspm=c2,
                           k1_a_npm=k1, k1_b_npm_per_kpa=0.0, k1_table=()).at(0.0)
        ss = state_space(lp)
        A.append(ss.A)
        B.append(ss.B)
    base = state_space(prior.at(0.0))
    return StateSpace(np.stack(A)[level_idx], np.stack(B)[level_idx], base.C, base.D)


def simulate_batch(
    batch: KeystrokeBatch, params: MSDParams
) -> tuple[FloatArray, FloatArray]:
    """Simulated x1, x2 (n, T) of the linear model driven by the batch's arm traces."""
    levels = tuple(sorted(set(np.abs(batch.vacuum_kpa).tolist())))
    idx = np.searchsorted(levels, np.abs(batch.vacuum_kpa))
    A, B = [], []
    for p in levels:
        ss = state_space(params.at(-p))
        A.append(ss.A)
        B.append(ss.B)
    base = state_space(params.at(0.0))
    ss = StateSpace(np.stack(A)[idx], np.stack(B)[idx], base.C, base.D)
    y = lsim_uniform(ss, batch.t_s, batch.x0_m[:, None, :])
    return y[:, 0, :], y[:, 1, :]


@dataclass
class _Problem:
    batch: KeystrokeBatch
    layout: _Layout
    prior: MSDParams
    level_idx: npt.NDArray[np.intp] = field(init=False)
    mask: npt.NDArray[np.bool_] = field(init=False)
    measured: FloatArray = field(init=False)
    measured_grid: FloatArray = field(init=False)

    def __post_init__(self) -> None:
        self.level_idx = np.searchsorted(self.layout.levels_kpa, np.abs(self.batch.vacuum_kpa))
        y = np.stack([self.batch.x1_m, self.batch.x2_m], axis=1)  # (n, 2, T)
        self.mask = np.isfinite(y)
        self.measured = y[self.mask] / RESIDUAL_SCALE_M
        self.measured_grid = np.where(self.mask, y, 0.0) / RESIDUAL_SCALE_M

    def residuals(self, theta: FloatArray) -> FloatArray:
        """Model minus measurement (mm) at every measured sample, rest offsets profiled out.

        Each trace is measured relative to a rest level estimated from a few noisy frames, so
        every keystroke's x1 and x2 carry an unknown constant offset (and an offset of the arm
        trace reaches both outputs as a constant through the static gain). Left in, that error
        is perfectly correlated over the whole keystroke; it is removed here as a nuisance
        parameter per keystroke and signal (variable projection: the mean residual).
        """
        ss = _systems(theta, self.layout, self.prior, self.level_idx)
        with np.errstate(over="ignore", invalid="ignore"):  # trial steps may be unstable
            y = lsim_uniform(ss, self.batch.t_s, self.batch.x0_m[:, None, :])
        full = np.where(self.mask, y / RESIDUAL_SCALE_M, 0.0) - self.measured_grid
        offset = full.sum(axis=2, keepdims=True) / np.maximum(self.mask.sum(axis=2, keepdims=True), 1)
        r = np.asarray((full - offset)[self.mask], dtype=np.float64)
        return np.where(np.isfinite(r), r, 1e6)

    def fit(self, theta0: FloatArray, loss: str = "soft_l1") -> FloatArray:
        # f_scale: residuals beyond ~0.1 mm are treated as outliers (mocap glitches, ghost frames).
        # Bounds: within a factor 1e3 of the prior model either way (in log space), so a
        # parameter the data cannot see stays finite instead of drifting to 0 or infinity.
        centre = self.layout.initial(self.prior)
        lo, hi = centre - math.log(1e3), centre + math.log(1e3)
        start = np.clip(theta0, lo + 1e-9, hi - 1e-9)
        res = least_squares(self.residuals, start, loss=loss, f_scale=0.1, x_scale=1.0,
                            method="trf", diff_step=1e-4, max_nfev=200, bounds=(lo, hi))
        return np.asarray(res.x, dtype=np.float64)


def _jacobian(problem: _Problem, theta: FloatArray, step: float = 1e-4) -> FloatArray:
    cols = []
    for j in range(theta.size):
        d = np.zeros_like(theta)
        d[j] = step
        cols.append((problem.residuals(theta + d) - problem.residuals(theta - d)) / (2 * step))
    return np.stack(cols, axis=1)


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


def _params_from_theta(theta: FloatArray, layout: _Layout, prior: MSDParams) -> MSDParams:
    v = np.exp(theta)
    nl = len(layout.levels_kpa)
    table = tuple((-p, float(v[j])) for j, p in enumerate(layout.levels_kpa))
    a, b = _law(np.asarray(layout.levels_kpa), v[:nl], prior)
    return prior.replace(
        k1_a_npm=a, k1_b_npm_per_kpa=b, k1_table=table,
        c1_nspm=float(v[nl]), k2_npm=float(v[nl + 1]), c2_nspm=float(v[nl + 2]),
        k0_npm=float(v[nl + 3]) if layout.free_coupling else None,
        c0_nspm=float(v[nl + 4]) if layout.free_coupling else None,
    )


def _law(levels: FloatArray, k1: FloatArray, prior: MSDParams) -> tuple[float, float]:
    """k1 = a + b|p| through the per-level values (one level: keep the prior slope)."""
    if levels.size < 2:
        b = prior.k1_b_npm_per_kpa
        return float(k1[0] - b * levels[0]), float(b)
    b, a = np.polyfit(levels, k1, 1)
    return float(a), float(b)


def _derived(theta: FloatArray, layout: _Layout, prior: MSDParams) -> dict[str, float]:
    """Every reported quantity as a function of theta (so bootstrap and delta method share it)."""
    v = np.exp(theta)
    nl = len(layout.levels_kpa)
    out = {name: float(x) for name, x in zip(layout.names, v, strict=True)}
    a, b = _law(np.asarray(layout.levels_kpa), v[:nl], prior)
    out["k1_a_npm"], out["k1_b_npm_per_kpa"] = a, b
    out["c1_over_m1_per_s"] = out["c1_nspm"] / prior.m1_kg
    out["c2_over_m2_per_s"] = out["c2_nspm"] / prior.m2_kg
    out["k2_over_m2_per_s2"] = out["k2_npm"] / prior.m2_kg
    return out


UNITS = {"c1_nspm": "N*s/m", "k2_npm": "N/m", "c2_nspm": "N*s/m", "k0_npm": "N/m",
         "c0_nspm": "N*s/m", "k1_a_npm": "N/m", "k1_b_npm_per_kpa": "N/m/kPa",
         "c1_over_m1_per_s": "1/s", "c2_over_m2_per_s": "1/s", "k2_over_m2_per_s2": "1/s^2"}


def _fit_once(batch: KeystrokeBatch, prior: MSDParams, free: bool, theta0: FloatArray | None) -> tuple[_Problem, FloatArray]:
    layout = _Layout(tuple(sorted(set(np.abs(batch.vacuum_kpa).tolist()))), free)
    problem = _Problem(batch, layout, prior)
    start = layout.initial(prior) if theta0 is None else theta0
    return problem, problem.fit(start)


def identify_trajectories(
    batch: KeystrokeBatch,
    *,
    prior: MSDParams | None = None,
    coupling: Coupling = "auto",
    bootstrap: int = 0,
    seed: int = 0,
) -> TrajectoryFit:
    """Fit the linear keystroke model to the batch (see the module docstring).

    Args:
        batch: keystrokes with arm input and measured fingertip/key trajectories.
        prior: starting values and the fixed masses (default: the published parameters).
        coupling: "tied" (k0 = k1, c0 = c1), "free", or "auto" (free only if BIC drops by > 10).
        bootstrap: number of bootstrap refits over keystrokes (0: Jacobian intervals only).
        seed: bootstrap random seed.
    """
    prior = prior or MSDParams()
    problem, theta = _fit_once(batch, prior, coupling == "free", None)
    bic = _bic(problem, theta)
    if coupling == "auto":
        lp = _params_from_theta(theta, problem.layout, prior).at(-problem.layout.levels_kpa[0])
        start = np.r_[theta, np.log([lp.k0_npm, lp.c0_nspm])]
        p_free, th_free = _fit_once(batch, prior, True, start)
        bic_free = _bic(p_free, th_free)
        if bic_free < bic - 10.0:
            problem, theta, bic = p_free, th_free, bic_free
    layout = problem.layout

    r = problem.residuals(theta)
    J = _jacobian(problem, theta)
    # Two honest estimates of the same covariance under different assumptions; keep the
    # larger variance of each parameter: the residual-based HAC sandwich (right under model
    # error, blind to errors the fit absorbs) and the measurement-noise propagation (right when
    # the model is correct, including noise on the arm trace that drives it).
    hac = hac_covariance(problem.mask, J, r)
    noise = noise_covariance(problem.mask, J, _impulse_responses(problem, theta), problem.level_idx,
                             [problem.batch.x0_m, problem.batch.x1_m, problem.batch.x2_m], RESIDUAL_SCALE_M)
    cov = larger_variances(hac, noise)
    point = _derived(theta, layout, prior)
    # Delta method for every derived quantity: gradient by finite differences in theta.
    jac_ci: dict[str, tuple[float, float]] = {}
    names = list(point)
    grads = np.zeros((len(names), theta.size))
    for j in range(theta.size):
        d = np.zeros_like(theta)
        d[j] = 1e-6
        up = _derived(theta + d, layout, prior)
        grads[:, j] = [(up[n] - point[n]) / 1e-6 for n in names]
    for i, n in enumerate(names):
        if n in layout.names:  # log-parameterised: multiplicative interval
            sd = math.sqrt(max(cov[layout.names.index(n), layout.names.index(n)], 0.0))
            half = Z95 * sd
            # An unidentified parameter (flat cost) gets an unbounded interval, not an overflow.
            jac_ci[n] = (point[n] * math.exp(-half), point[n] * math.exp(half)) if half < 50 else (0.0, math.inf)
        else:
            sd = math.sqrt(max(float(grads[i] @ cov @ grads[i]), 0.0))
            jac_ci[n] = (point[n] - Z95 * sd, point[n] + Z95 * sd)

    boot_ci: dict[str, tuple[float, float]] = {}
    if bootstrap > 0 and batch.n >= 3:
        rng = np.random.default_rng(seed)
        draws = []
        for _ in range(bootstrap):
            idx = rng.integers(0, batch.n, batch.n)
            sub = batch.subset(idx)
            # A draw must contain every vacuum level, or its k1 is undefined: redraw per level.
            if len(set(np.abs(sub.vacuum_kpa))) < len(layout.levels_kpa):
                idx = np.concatenate([
                    rng.choice(np.flatnonzero(np.abs(batch.vacuum_kpa) == p), int((np.abs(batch.vacuum_kpa) == p).sum()))
                    for p in layout.levels_kpa
                ])
                sub = batch.subset(idx)
            sub_problem = _Problem(sub, layout, prior)
            draws.append(_derived(sub_problem.fit(theta), layout, prior))
        for n in names:
            vals = np.array([d[n] for d in draws])
            boot_ci[n] = (float(np.percentile(vals, 2.5)), float(np.percentile(vals, 97.5)))

    estimates = tuple(
        Estimate(n, point[n], UNITS.get(n, "N/m"), jac_ci[n], boot_ci.get(n)) for n in names
    )
    return TrajectoryFit(
        params=_params_from_theta(theta, layout, prior),
        estimates=estimates,
        coupling="free" if layout.free_coupling else "tied",
        rms_m=float(math.sqrt(float(r @ r) / r.size)) * RESIDUAL_SCALE_M,
        n_keystrokes=batch.n,
        n_samples=int(r.size),
        bic=bic,
        fixed={"m1_kg": prior.m1_kg, "m2_kg": prior.m2_kg},
    )


def _impulse_responses(problem: _Problem, theta: FloatArray) -> FloatArray:
    """x1, x2 response (levels, 2, T) of each level's model to one unit input sample."""
    T = problem.batch.t_s.size
    ss = _systems(theta, problem.layout, problem.prior, np.arange(len(problem.layout.levels_kpa)))
    hat = np.zeros((len(problem.layout.levels_kpa), 1, T))
    hat[:, 0, 1] = 1.0  # a unit sample at index 1 (the system rests at 0 before it)
    h = np.zeros((hat.shape[0], 2, T))
    h[..., : T - 1] = lsim_uniform(ss, problem.batch.t_s, hat)[..., 1:]
    return h


def _bic(problem: _Problem, theta: FloatArray) -> float:
    r = problem.residuals(theta)
    return float(r.size * math.log(float(r @ r) / r.size + 1e-300) + theta.size * math.log(r.size))


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
