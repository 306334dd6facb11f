"""The least-squares problem behind `identify`: parameter layout, residuals, derivatives, fit.

Parameters live in log space (positive, multiplicative intervals): k1 per vacuum level, c1, k2,
c2, and with free coupling k0 and c0. The residuals are model minus measurement (mm) at every
measured frame of x1 and x2, with each keystroke's rest offsets profiled out; the model is the
physical keystroke of `identify_forward` (free approach, touch, coupled press).

Derivatives are central differences with a step of 1 % in log space: the simulator switches the
coupling on at the first integration step (0.1 ms) after touch, so the trajectories move in tiny
steps as the touch instant crosses a step boundary; a 1 % change moves the touch by many steps,
which averages those out, while the curvature error of a central difference stays ~1e-4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from pianobot.analysis.greybox.covariance import noise_sigma_m
from pianobot.analysis.greybox.forward import ForwardModel
from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.physics.msd import MSDParams

FloatArray = npt.NDArray[np.float64]

#: Residuals are in millimetres so the robust loss scale reads naturally (0.05 mm ≈ mocap noise ×10).
RESIDUAL_SCALE_M = 1.0e-3
#: Residuals are capped here (1 m in residual units): far beyond any keystroke's travel.
MAX_RESIDUAL = 1e3
#: Central-difference step in log-parameters (see the module docstring).
JAC_STEP = 1e-2
#: Noise draws that propagate the arm trace's noise through the model, and their amplification
#: (the response is linear in the noise; amplifying lifts it above the touch-step granularity).
INPUT_NOISE_DRAWS = 32
INPUT_NOISE_GAIN = 10.0


def k1_name(vacuum_kpa: float) -> str:
    """Name of the per-level stiffness, e.g. `k1_npm@-40kPa`."""
    return f"k1_npm@{-abs(vacuum_kpa):g}kPa"


@dataclass(frozen=True)
class Layout:
    """Which entries of the log-parameter vector mean what."""

    levels_kpa: tuple[float, ...]  # |p|, ascending
    free_coupling: bool

    @classmethod
    def of(cls, batch: KeystrokeBatch, free_coupling: bool) -> Layout:
        return cls(tuple(sorted(set(np.abs(batch.vacuum_kpa).tolist()))), free_coupling)

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

    def params(self, theta: FloatArray, prior: MSDParams) -> MSDParams:
        """The model of log-parameters theta (k1_table holds the per-level stiffness)."""
        v = np.exp(theta)
        nl = len(self.levels_kpa)
        table = tuple((-p, float(v[j])) for j, p in enumerate(self.levels_kpa))
        a, b = k1_law(np.asarray(self.levels_kpa), v[:nl], prior)
        return prior.replace(
            k1_a_npm=a, k1_b_npm_per_kpa=b, k1_table=table,
            c1_nspm=float(v[nl]), k2_npm=float(v[nl + 1]), c2_nspm=float(v[nl + 2]),
            k0_npm=float(v[nl + 3]) if self.free_coupling else None,
            c0_nspm=float(v[nl + 4]) if self.free_coupling else None,
        )


def k1_law(levels: FloatArray, k1: FloatArray, prior: MSDParams) -> tuple[float, float]:
    """k1 = a + b|p| through the per-level values (one level: keep the prior slope)."""
    if levels.size < 2:
        b = prior.k1_b_npm_per_kpa
        return float(k1[0] - b * levels[0]), float(b)
    b, a = np.polyfit(levels, k1, 1)
    return float(a), float(b)


@dataclass
class Problem:
    """Residuals of one batch under one layout and prior (the masses come from the prior)."""

    batch: KeystrokeBatch
    layout: Layout
    prior: MSDParams
    forward: ForwardModel = field(init=False)
    mask: npt.NDArray[np.bool_] = field(init=False)
    measured_grid: FloatArray = field(init=False)
    _last: tuple[FloatArray, FloatArray] | None = field(init=False, default=None)

    def __post_init__(self) -> None:
        self.forward = ForwardModel.of(self.batch)
        y = np.stack([self.batch.x1_m, self.batch.x2_m], axis=1)  # (n, 2, T)
        # Measured samples inside the model's domain (before lift-off: `model_window`).
        inside = np.arange(y.shape[2])[None, :] <= self.forward.last[self.forward.rows][:, None]
        self.mask = np.isfinite(y) & inside[:, None, :]
        self.measured_grid = np.where(self.mask, y, 0.0) / RESIDUAL_SCALE_M

    def simulate(self, theta: FloatArray, input_x0_m: FloatArray | None = None) -> FloatArray:
        """Model x1, x2 (n, 2, T) in residual units for log-parameters theta."""
        x1, x2 = self.forward.simulate(self.layout.params(theta, self.prior), input_x0_m)
        return np.stack([x1, x2], axis=1) / RESIDUAL_SCALE_M

    def profiled(self, full: FloatArray) -> FloatArray:
        """Masked samples of (n, 2, T) differences with each row's mean removed.

        Each trace is measured relative to a rest level estimated from a few noisy frames, so
        every keystroke's x1 and x2 carry an unknown constant offset (and an offset of the arm
        trace reaches both outputs as a constant through the static gain). Left in, that error
        is perfectly correlated over the whole keystroke; it is removed here as a nuisance
        parameter per keystroke and signal (variable projection: the mean residual).
        """
        full = np.where(self.mask, full, 0.0)
        offset = full.sum(axis=2, keepdims=True) / np.maximum(self.mask.sum(axis=2, keepdims=True), 1)
        return np.asarray((full - offset)[self.mask], dtype=np.float64)

    def residuals(self, theta: FloatArray) -> FloatArray:
        """Model minus measurement (mm) at every measured sample, rest offsets profiled out."""
        with np.errstate(over="ignore", invalid="ignore"):  # trial steps may be unstable
            r = self.profiled(self.simulate(theta) - self.measured_grid)
        # A diverged trial simulation reads as a uniformly bad fit, never as NaN or overflow.
        r = np.clip(np.where(np.isfinite(r), r, MAX_RESIDUAL), -MAX_RESIDUAL, MAX_RESIDUAL)
        self._last = (theta.copy(), r)
        return r

    def jacobian(self, theta: FloatArray, *, central: bool = True) -> FloatArray:
        """Differences of the residuals in log-parameters (step `JAC_STEP`).

        Central differences for the intervals; the fit's iterations use forward differences
        from the residuals it has just computed (half the simulations: the direction of a step
        needs less accuracy than an interval, and the optimum does not depend on it).
        """
        base = None if central else self._cached(theta)
        cols = []
        for j in range(theta.size):
            d = np.zeros_like(theta)
            d[j] = JAC_STEP
            if base is None:
                cols.append((self.residuals(theta + d) - self.residuals(theta - d)) / (2 * JAC_STEP))
            else:
                cols.append((self.residuals(theta + d) - base) / JAC_STEP)
        return np.stack(cols, axis=1)

    def _cached(self, theta: FloatArray) -> FloatArray:
        """The residuals at theta, reusing the last evaluation when it was at the same point."""
        if self._last is not None and np.array_equal(self._last[0], theta):
            return self._last[1]
        return self.residuals(theta)

    def fit(self, theta0: FloatArray, loss: str = "soft_l1") -> FloatArray:
        """Robust least squares from theta0, within a factor 1e3 of the prior either way."""
        # f_scale: residuals beyond ~0.1 mm are treated as outliers (mocap glitches, ghost frames).
        # Bounds keep a parameter the data cannot see finite instead of drifting to 0 or infinity.
        centre = self.layout.initial(self.prior)
        lo, hi = centre - math.log(1e3), centre + math.log(1e3)
        start = np.clip(theta0, lo + 1e-9, hi - 1e-9)
        res = least_squares(self.residuals, start, jac=lambda th: self.jacobian(th, central=False),
                            loss=loss, f_scale=0.1,
                            x_scale=1.0, method="trf", max_nfev=200, bounds=(lo, hi), ftol=1e-6, xtol=1e-6)
        return np.asarray(res.x, dtype=np.float64)

    def bic(self, theta: FloatArray) -> float:
        r = self.residuals(theta)
        return float(r.size * math.log(float(r @ r) / r.size + 1e-300) + theta.size * math.log(r.size))

    def output_noise(self, theta: FloatArray) -> tuple[float, float]:
        """White-noise σ of the measured x1 and x2 (residual units), from the residuals' second
        differences at theta.

        The traces' own second differences would count the motion's curvature as noise (at
        120 frames/s the finger's and key's ringing curves by several µm per frame); what the
        model explains is gone from the residuals, and differencing removes what is left of
        any smooth model error, so this reads the noise alone.
        """
        with np.errstate(over="ignore", invalid="ignore"):
            full = np.where(self.mask, self.simulate(theta) - self.measured_grid, np.nan)
        return noise_sigma_m(full[:, 0]), noise_sigma_m(full[:, 1])

    def input_noise_scores(self, theta: FloatArray, J: FloatArray, seed: int = 0) -> FloatArray:
        """Jᵀ·(model response to one draw of the arm trace's noise), one row per seeded draw.

        White noise of the measured level on every input sample, referred to its rest level as
        the measured trace was, pushed through the model. The
        response is linear in the noise; it is computed for amplified noise and scaled back, so
        that it stands clear of the touch instant's step granularity.
        """
        batch = self.batch
        sigma = batch.input_noise_m
        if not (sigma > 0 or batch.clock_offset_se_s > 0):
            return np.zeros((0, theta.size))
        rng = np.random.default_rng(seed)
        base = self.simulate(theta)
        before = batch.input_t_s < 0.0
        speed = np.gradient(batch.input_x0_m, batch.input_t_s, axis=1) if batch.input_t_s.size > 1 else 0.0
        scores = []
        for _ in range(INPUT_NOISE_DRAWS):
            noise = rng.normal(0.0, INPUT_NOISE_GAIN * sigma, batch.input_x0_m.shape)
            # The trace is measured relative to a rest level read from the same noisy samples
            # (the median before motion start, else the first sample): that error shifts the
            # whole trace, and with it the instant the fingertip reaches the key.
            rest = np.median(noise[:, before], axis=1) if before.any() else noise[:, 0]
            noise -= rest[:, None]
            # The clock offset that put the arm log on the mocap clock is estimated too: one
            # error shifts every keystroke's input in time, x0(t − δτ) ≈ x0(t) − δτ·ẋ0(t).
            noise -= rng.normal(0.0, INPUT_NOISE_GAIN * batch.clock_offset_se_s) * speed
            with np.errstate(over="ignore", invalid="ignore"):
                dy = self.profiled(self.simulate(theta, batch.input_x0_m + noise) - base) / INPUT_NOISE_GAIN
            scores.append(J.T @ np.where(np.isfinite(dy), dy, 0.0))
        return np.asarray(scores, dtype=np.float64)
