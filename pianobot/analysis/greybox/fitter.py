"""The one least-squares fitter of the grey-box model: identification and discovery configure it.

`GreyBoxFit(drive, layout).fit()` adjusts the layout's free parameters so that the drive's
predictions match the batch, and returns itself with the learned attributes (scikit-learn
style): `theta_`, `params_`, `model_`, `drive_`, `channels_` (raw residuals per channel),
`sigma_`, `rms_m_`, `on_bounds_`, `converged_` (False: stopped by `max_nfev`), `nfev_`;
`covariance()` sets `cov_`.

Residual channels (model minus measurement):

- trajectories (`x1`, `x2`): every measured frame inside the model's window (before the
  fingertip lifts off the key), with each keystroke's rest offsets profiled out (every trace is
  measured from a rest level read off a few noisy frames: an unknown constant per keystroke and
  signal, removed as a nuisance parameter — variable projection);
- MIDI (`on_velocity`, `hold_s`, `t_on_s` where both sounded; `sound`: by how much the key
  missed the trigger depth where the piano sounded, or passed it where it stayed silent).

Each channel is divided by its error level σ = √(noise² + systematic²): the robust loss
(soft-L1, quadratic up to 3σ, linear beyond: ghost frames and piano misfires weigh little)
then means the same on every channel, and channels of different units add up. σ comes from the
residuals themselves (two passes: at the start, then at the first optimum), or is given, so
that candidate models of one discovery are all judged on one scale.

A fit ends where least squares' tolerances say, where its budget (`max_nfev`) runs out, or where
it has stalled (`Stall`): its cost fell by less than `STALL_RTOL` of itself over the last
`STALL_ITERATIONS` iterations. A fit that bends the base model to imitate a missing effect, or
holds a parameter the data hardly see, crawls along a flat valley for a hundred evaluations or
more, each a simulation of every keystroke, for a few hundredths of a percent of its error.

Derivatives are differences with a step of 1 % in internal units: the simulator switches the
coupling on at the first integration step after touch, so trajectories move in tiny steps as
the touch instant crosses a step boundary; a 1 % change moves the touch by many steps, which
averages those out, while the curvature error of a central difference stays ~1e-4. A fit steps
on forward differences (the direction of a step needs less accuracy); the covariance, and a fit
asked to finish (`central=True`), use central ones: near an optimum the forward difference's
first-order error at this step points each step a little off the valley, and the fit crawls.

Linear algebra runs on one BLAS thread: the Jacobians are tall and thin (tens of thousands of
frames × about ten parameters), where threads gain nothing, and on a shared machine (or in an
executor's worker, one per core) OpenBLAS's spinning threads cost up to 20× the CPU of one
thread for the trust-region solver's SVD (measured in benchmarks/bench_discover.py's runs).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt
from scipy.optimize import OptimizeResult, least_squares
from threadpoolctl import threadpool_limits

from pianobot.analysis.greybox.covariance import (
    hac_covariance,
    larger_variances,
    noise_covariance,
    unseen_unknown,
)
from pianobot.analysis.greybox.forward import MeasuredArm
from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.analysis.greybox.layout import Layout
from pianobot.analysis.greybox.noise import (
    MIDI_TIME_SIGMA_S,
    VELOCITY_QUANTUM_SIGMA,
    noise_sigma_m,
    rms,
)
from pianobot.analysis.greybox.prediction import Prediction
from pianobot.physics.model import KeystrokeModel

FloatArray = npt.NDArray[np.float64]

TRAJECTORY_CHANNELS: tuple[str, ...] = ("x1", "x2")
MIDI_CHANNELS: tuple[str, ...] = ("on_velocity", "hold_s", "t_on_s", "sound")
#: Noise floors of the MIDI channels (velocity rounding, the 1 ms clock, 0.1 mm of key travel).
MIDI_FLOORS: dict[str, float] = {"on_velocity": VELOCITY_QUANTUM_SIGMA, "hold_s": MIDI_TIME_SIGMA_S * np.sqrt(2.0),
                                 "t_on_s": MIDI_TIME_SIGMA_S, "sound": 1e-4}
#: The robust loss is quadratic up to this many σ.
LOSS_SCALE_SIGMAS = 3.0
#: Residuals are capped here (in σ): a diverged trial simulation reads as a uniformly bad fit.
MAX_RESIDUAL = 1e6
JAC_STEP = 1e-2
#: A fit has stalled when its cost fell by less than this fraction of itself over the last
#: `STALL_ITERATIONS` iterations (see `Stall`).
STALL_RTOL = 1e-4
STALL_ITERATIONS = 10
#: Noise draws that propagate the arm trace's noise through the model, and their amplification
#: (the response is linear in the noise; amplifying lifts it above the touch-step granularity).
INPUT_NOISE_DRAWS = 32
INPUT_NOISE_GAIN = 10.0


class Drive(Protocol):
    """What drives the forward model over a batch (measured arm or commanded press)."""

    @property
    def observed(self) -> KeystrokeBatch: ...

    def predict(self, model: KeystrokeModel, drive: dict[str, float] | None = None) -> Prediction: ...


@dataclass(frozen=True)
class Residuals:
    """Raw residuals (model − measurement, natural units) per channel, with where they sit."""

    values: dict[str, FloatArray]  # channel -> 1-D residuals
    keystroke: dict[str, npt.NDArray[np.intp]]  # channel -> row of each residual
    frame: dict[str, npt.NDArray[np.intp]]  # channel -> frame index (0 for MIDI)

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(c for c, v in self.values.items() if v.size)


class Stall:
    """`least_squares`' callback that ends a fit crawling along a flat valley.

    The crawl gains nothing the criterion can see: on the effective sample sizes it counts
    (hundreds of independent samples at most), a relative change δ of the error moves the
    criterion by about n_eff·δ, and a fit that stalls at 1e-4 per 10 iterations leaves
    ~1e-3 undone even if it would have crawled 200 iterations more: under 1, against a
    decision threshold of 10. Measured on the tied base fit of the independent weak rest-stop
    take: 50 evaluations instead of 76, at 0.72494 mm RMS instead of 0.72490 mm
    (tests/analysis/test_fitter_stall.py).
    """

    def __init__(self, iterations: int, rtol: float) -> None:
        self.iterations = iterations
        self.rtol = rtol
        self.costs: list[float] = []

    def __call__(self, intermediate_result: OptimizeResult) -> None:
        self.costs.append(float(intermediate_result.cost))
        if len(self.costs) > self.iterations:
            before, now = self.costs[-self.iterations - 1], self.costs[-1]
            if before - now < self.rtol * now:
                raise StopIteration  # least_squares returns with status -2


class GreyBoxFit:
    """Output-error least squares of a layout's parameters under one drive (module docstring)."""

    def __init__(self, drive: Drive, layout: Layout, *, channels: tuple[str, ...] | None = None,
                 sigma: Mapping[str, float] | None = None, max_nfev: int = 200, tol: float = 1e-6,
                 central: bool = False) -> None:
        self.drive = drive
        self.batch = drive.observed
        self.layout = layout
        self.max_nfev = max_nfev
        self.tol = tol
        self.central = central
        batch = self.batch
        if channels is None:
            channels = TRAJECTORY_CHANNELS if batch.has_motion else MIDI_CHANNELS
        self.channels = channels
        self.sigma: dict[str, float] = dict(sigma or {})
        y = np.stack([batch.x1_m, batch.x2_m], axis=1)  # (n, 2, T)
        last = drive.last[drive.rows] if isinstance(drive, MeasuredArm) else np.full(batch.n, batch.t_s.size - 1)
        inside = np.arange(y.shape[2])[None, :] <= last[:, None]
        use = np.array([c in channels for c in TRAJECTORY_CHANNELS])
        self.mask = np.isfinite(y) & inside[:, None, :] & use[None, :, None]
        self._where = np.nonzero(self.mask)  # (keystroke, signal, frame) of each masked sample
        self._last: tuple[FloatArray, FloatArray] | None = None
        self.converged_ = False  # set by `fit` (an `evaluate`d model was not fitted)
        self.nfev_ = 0  # residual evaluations of `fit` (the Jacobians' are not counted)

    # ---- residuals --------------------------------------------------------------------------

    def profiled(self, full: FloatArray) -> FloatArray:
        """Masked samples of (n, 2, T) differences with each row's mean removed (rest offsets)."""
        full = np.where(self.mask, full, 0.0)
        offset = full.sum(axis=2, keepdims=True) / np.maximum(self.mask.sum(axis=2, keepdims=True), 1)
        return np.asarray((full - offset)[self.mask], dtype=np.float64)

    def _by_channel(self, masked: FloatArray) -> tuple[FloatArray, ...]:
        """A vector in mask order (row-major over keystroke, signal, frame) split by signal."""
        signal = self._where[1]
        return tuple(masked[signal == c] for c in range(len(TRAJECTORY_CHANNELS)))

    def predict(self, theta: FloatArray) -> Prediction:
        with np.errstate(over="ignore", invalid="ignore"):
            return self.drive.predict(self.layout.model(theta), self.layout.drive(theta))

    def raw(self, prediction: Prediction) -> Residuals:
        """Residuals of a prediction, per channel, in natural units (m, MIDI units, s)."""
        batch = self.batch
        values: dict[str, FloatArray] = {}
        rows: dict[str, npt.NDArray[np.intp]] = {}
        frames: dict[str, npt.NDArray[np.intp]] = {}
        if self.mask.any():
            sim = np.stack([prediction.x1_m, prediction.x2_m], axis=1)
            y = np.stack([batch.x1_m, batch.x2_m], axis=1)
            with np.errstate(over="ignore", invalid="ignore"):
                r = self.profiled(sim - y)
            idx = self._where
            for name, part in zip(TRAJECTORY_CHANNELS, self._by_channel(r), strict=True):
                sel = idx[1] == TRAJECTORY_CHANNELS.index(name)
                values[name], rows[name], frames[name] = part, idx[0][sel], idx[2][sel]
        heard = batch.sounded == 1.0
        for name, model_v, measured in (("on_velocity", prediction.on_velocity, batch.on_velocity),
                                        ("hold_s", prediction.hold_s, batch.hold_midi_s),
                                        ("t_on_s", prediction.t_on_s, batch.t_on_s)):
            if name not in self.channels:
                continue
            # One slot per keystroke the piano sounded (a fixed length for the optimiser); where
            # the model stays silent it says 0 (no velocity, no hold), so a silent model is never
            # a cheap one, while the `sound` channel gives the slope towards sounding.
            sel = np.flatnonzero(heard & np.isfinite(measured))
            model_at = np.where(np.isfinite(model_v[sel]), model_v[sel], 0.0 if name != "t_on_s" else measured[sel])
            values[name], rows[name], frames[name] = model_at - measured[sel], sel, np.zeros(sel.size, np.intp)
        if "sound" in self.channels:
            known = np.flatnonzero(np.isfinite(batch.sounded))
            m = prediction.margin_m[known]
            heard = batch.sounded[known] == 1.0
            miss = np.where(heard, np.minimum(m, 0.0), np.maximum(m, 0.0))
            values["sound"], rows["sound"], frames["sound"] = np.nan_to_num(miss), known, np.zeros(known.size, np.intp)
        return Residuals(values, rows, frames)

    def scaled(self, res: Residuals) -> FloatArray:
        """One residual vector: every channel divided by its σ, capped."""
        parts = [res.values[c] / max(self.sigma.get(c, 1.0), 1e-300) for c in self.channels if c in res.values]
        r = np.concatenate(parts) if parts else np.zeros(0)
        return np.clip(np.where(np.isfinite(r), r, MAX_RESIDUAL), -MAX_RESIDUAL, MAX_RESIDUAL)

    def residuals(self, theta: FloatArray) -> FloatArray:
        r = self.scaled(self.raw(self.predict(theta)))
        self._last = (theta.copy(), r)
        return r

    def residuals_many(self, thetas: list[FloatArray]) -> list[FloatArray]:
        """`residuals` at several points, predicted together where the drive can
        (`MeasuredArm.predict_many`: the same numbers, the simulator's blocks better filled)."""
        many = getattr(self.drive, "predict_many", None)
        if many is None or len(thetas) < 2:
            return [self.residuals(theta) for theta in thetas]
        with np.errstate(over="ignore", invalid="ignore"):
            predictions = many([self.layout.model(theta) for theta in thetas],
                               [self.layout.drive(theta) for theta in thetas])
        out = [self.scaled(self.raw(prediction)) for prediction in predictions]
        self._last = (thetas[-1].copy(), out[-1])
        return out

    def jacobian(self, theta: FloatArray, *, central: bool = True) -> FloatArray:
        """Differences of the scaled residuals in internal units (step `JAC_STEP`)."""
        base = None
        if not central:
            base = self._last[1] if self._last is not None and np.array_equal(self._last[0], theta) else self.residuals(theta)
        lo, hi = self.layout.bounds()
        points, spans = [], []
        for j in range(theta.size):
            d = np.zeros_like(theta)
            d[j] = JAC_STEP
            if base is None:
                up, down = np.minimum(theta + d, hi), np.maximum(theta - d, lo)
                points += [up, down]
                spans.append(max(float(up[j] - down[j]), 1e-12))
            else:
                step = d if theta[j] + JAC_STEP <= hi[j] else -d
                points.append(theta + step)
                spans.append(float(step[j]))
        r = self.residuals_many(points)
        if base is None:
            cols = [(r[2 * j] - r[2 * j + 1]) / spans[j] for j in range(theta.size)]
        else:
            cols = [(r[j] - base) / spans[j] for j in range(theta.size)]
        return np.stack(cols, axis=1) if cols else np.zeros((base.size if base is not None else 0, 0))

    # ---- error levels -----------------------------------------------------------------------

    def noise(self, res: Residuals) -> dict[str, float]:
        """White-noise σ per channel: second differences of the trajectory residuals along each
        keystroke; the stated floors for MIDI."""
        out: dict[str, float] = {}
        for name in TRAJECTORY_CHANNELS:
            if name in res.values and res.values[name].size:
                full = np.full(self.mask.shape[::2], np.nan)
                full[res.keystroke[name], res.frame[name]] = res.values[name]
                out[name] = noise_sigma_m(full)
        for name in MIDI_CHANNELS:
            if name in res.values:
                out[name] = MIDI_FLOORS[name]
        return out

    def error_levels(self, res: Residuals) -> dict[str, float]:
        """σ per channel = √(noise² + systematic²) = the residual RMS, floored at the noise."""
        noise = self.noise(res)
        return {c: max(rms(v), noise.get(c, 0.0), 1e-12) for c, v in res.values.items() if v.size}

    # ---- fit -------------------------------------------------------------------------------

    def fit(self, theta0: FloatArray | None = None) -> GreyBoxFit:
        """Robust least squares from theta0 (default: the layout's start) within the bounds."""
        with threadpool_limits(1, user_api="blas"):
            return self._fit(theta0)

    def _fit(self, theta0: FloatArray | None) -> GreyBoxFit:
        lo, hi = self.layout.bounds()
        theta = np.clip(self.layout.start() if theta0 is None else np.asarray(theta0, float), lo + 1e-9, hi - 1e-9)
        fixed_sigma = bool(self.sigma)
        self.converged_ = True
        self.nfev_ = 0
        passes = 1 if fixed_sigma else 2
        for _ in range(passes):
            if not fixed_sigma:
                self.sigma = self.error_levels(self.raw(self.predict(theta)))
            if theta.size:
                result = least_squares(self.residuals, theta, jac=lambda th: self.jacobian(th, central=self.central),
                                       loss="soft_l1", f_scale=LOSS_SCALE_SIGMAS, x_scale=1.0, method="trf",
                                       max_nfev=self.max_nfev, bounds=(lo, hi), ftol=self.tol, xtol=self.tol,
                                       callback=Stall(STALL_ITERATIONS, STALL_RTOL))
                theta = np.asarray(result.x, dtype=np.float64)
                self.nfev_ += int(result.nfev)
                self.converged_ = bool(result.status != 0)  # 0: the budget ran out (-2: stalled)
        self._finish(theta)
        return self

    def evaluate(self, theta: FloatArray) -> GreyBoxFit:
        """Set the learned attributes at theta without fitting (a fixed model)."""
        theta = np.asarray(theta, dtype=np.float64)
        if not self.sigma:
            self.sigma = self.error_levels(self.raw(self.predict(theta)))
        self._finish(theta)
        return self

    def _finish(self, theta: FloatArray) -> None:
        self.theta_ = theta
        self.params_ = self.layout.values(theta)
        self.model_ = self.layout.model(theta)
        self.drive_ = self.layout.drive(theta)
        self.prediction_ = self.predict(theta)
        self.residuals_ = self.raw(self.prediction_)
        self.channels_ = self.residuals_.values
        traj = [v for c, v in self.channels_.items() if c in TRAJECTORY_CHANNELS]
        self.rms_m_ = rms(np.concatenate(traj)) if traj else float("nan")
        self.on_bounds_ = self.layout.on_bounds(theta)
        self.n_samples_ = int(sum(v.size for v in self.channels_.values()))

    # ---- covariance -------------------------------------------------------------------------

    def covariance(self, seed: int = 0) -> FloatArray:
        """Covariance of theta: per parameter the larger of the HAC sandwich (honest under model
        error) and the noise propagation (honest when the model is right, and the only one that
        sees input noise the fit absorbs); sets `cov_`."""
        with threadpool_limits(1, user_api="blas"):
            return self._covariance(seed)

    def _covariance(self, seed: int) -> FloatArray:
        theta = self.theta_
        r = self.residuals(theta)
        J = self.jacobian(theta)
        series, position = self._slots()
        hac = hac_covariance(J, r, series, position, n_offsets=int(np.count_nonzero(self.mask.any(axis=2))))
        noise = noise_covariance(J, self._noise_per_residual(), self.input_noise_scores(theta, J, seed))
        self.cov_ = unseen_unknown(larger_variances(hac, noise), J)
        self.jacobian_ = J
        return self.cov_

    def _slots(self) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
        """Per scaled residual: its series (a keystroke's trajectory, or one MIDI residual) and
        its position in time; x1 and x2 at one instant share a slot (they share the input)."""
        res = self.residuals_
        series, position = [], []
        next_series = self.batch.n
        for c in self.channels:
            if c not in res.values:
                continue
            if c in TRAJECTORY_CHANNELS:
                series.append(res.keystroke[c])
                position.append(res.frame[c])
            else:
                k = res.values[c].size
                series.append(np.arange(next_series, next_series + k))
                position.append(np.zeros(k, dtype=np.intp))
                next_series += k
        if not series:
            return np.zeros(0, np.intp), np.zeros(0, np.intp)
        return np.concatenate(series).astype(np.intp), np.concatenate(position).astype(np.intp)

    def _noise_per_residual(self) -> FloatArray:
        noise = self.noise(self.residuals_)
        parts = [np.full(self.residuals_.values[c].size, noise.get(c, 0.0) / max(self.sigma.get(c, 1.0), 1e-300))
                 for c in self.channels if c in self.residuals_.values]
        return np.concatenate(parts) if parts else np.zeros(0)

    def input_noise_scores(self, theta: FloatArray, J: FloatArray, seed: int = 0) -> FloatArray:
        """Jᵀ·(model response to one draw of the arm trace's noise), one row per seeded draw.

        White noise of the measured level on every input sample, referred to its rest level as
        the measured trace was, pushed through the model (measured-arm drive only). The response
        is linear in the noise; it is computed for amplified noise and scaled back, so that it
        stands clear of the touch instant's step granularity.
        """
        batch, drive = self.batch, self.drive
        sigma = batch.input_noise_m
        if not isinstance(drive, MeasuredArm) or not (sigma > 0 or batch.clock_offset_se_s > 0) or not self.mask.any():
            return np.zeros((0, theta.size))
        rng = np.random.default_rng(seed)
        model = self.layout.model(theta)
        scale = np.array([1.0 / max(self.sigma.get(c, 1.0), 1e-300) for c in TRAJECTORY_CHANNELS])[None, :, None]
        base = np.stack(drive.simulate(model), axis=1)
        before = batch.input_t_s < 0.0
        speed = np.gradient(batch.input_x0_m, batch.input_t_s, axis=1) if batch.input_t_s.size > 1 else 0.0
        scores = []
        for _ in range(INPUT_NOISE_DRAWS):
            noise = rng.normal(0.0, INPUT_NOISE_GAIN * sigma, batch.input_x0_m.shape)
            # The trace is measured relative to a rest level read from the same noisy samples:
            # that error shifts the whole trace, and with it the instant the fingertip touches.
            rest = np.median(noise[:, before], axis=1) if before.any() else noise[:, 0]
            noise -= rest[:, None]
            # The clock offset that put the arm log on the mocap clock is estimated too: one
            # error shifts every keystroke's input in time, x0(t − δτ) ≈ x0(t) − δτ·ẋ0(t).
            noise -= rng.normal(0.0, INPUT_NOISE_GAIN * batch.clock_offset_se_s) * speed
            with np.errstate(over="ignore", invalid="ignore"):
                moved = np.stack(drive.simulate(model, batch.input_x0_m + noise), axis=1)
                dy = self.profiled((moved - base) * scale) / INPUT_NOISE_GAIN
            parts = dict(zip(TRAJECTORY_CHANNELS, self._by_channel(np.where(np.isfinite(dy), dy, 0.0)), strict=True))
            full = np.concatenate([parts[c] if c in parts else np.zeros(self.residuals_.values[c].size)
                                   for c in self.channels if c in self.residuals_.values])
            scores.append(J.T @ full)
        return np.asarray(scores, dtype=np.float64)
