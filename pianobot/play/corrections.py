"""The two online estimators the play adapter combines: a global linear map and a local residual.

`RLS2` fits y ≈ θ0 + θ1·x by recursive least squares with forgetting, step bounds and clamps:
a different piano or a drifted finger scales and shifts the model's predictions everywhere.

`LocalCorrection` learns what is left over as a function of the down velocity, near the speeds
actually played: Gaussian-process (kernel) regression of the residuals with a short length
scale, each observation down-weighted by its age (forgetting) and clipped (bounded influence).
A stiffer finger does not only scale the model's loudness map, it changes its shape: the key's
speed between the piano's two sensors depends on whether finger and key separate and re-contact
on the way down, so the true map has plateaus and steps a smooth model does not have. A residual
with a length scale of a few percent of the speed range learns those near the notes played and
falls back to the global correction (with a larger variance) away from them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.linalg import solve_triangular

FloatArray = npt.NDArray[np.float64]


@dataclass
class RLS2:
    """Recursive least squares for y ≈ θ0 + θ1·x, with forgetting, step bounds and clamps."""

    theta: FloatArray  # [offset, gain]
    P: FloatArray  # 2×2 covariance
    forgetting: float
    max_step: FloatArray  # largest change of each parameter per update
    lower: FloatArray
    upper: FloatArray

    @classmethod
    def prior(cls, *, offset_sd: float, gain_sd: float, max_step: tuple[float, float],
              bounds: tuple[tuple[float, float], tuple[float, float]], forgetting: float) -> RLS2:
        """Start at the identity map (offset 0, gain 1) with the given prior spreads."""
        return cls(
            theta=np.array([0.0, 1.0]),
            P=np.diag([offset_sd**2, gain_sd**2]),
            forgetting=forgetting,
            max_step=np.asarray(max_step, dtype=np.float64),
            lower=np.array([bounds[0][0], bounds[1][0]]),
            upper=np.array([bounds[0][1], bounds[1][1]]),
        )

    def predict(self, x: npt.ArrayLike) -> FloatArray:
        """θ0 + θ1·x for each x."""
        return np.asarray(self.theta[0] + self.theta[1] * np.asarray(x, dtype=np.float64), dtype=np.float64)

    def update(self, x: float, y: float, noise_var: float) -> None:
        """One observation y at regressor x (`noise_var`: the observation's variance)."""
        phi = np.array([1.0, x])
        Pphi = self.P @ phi
        gain = Pphi / (self.forgetting * noise_var + phi @ Pphi)
        step = np.clip(gain * (y - phi @ self.theta), -self.max_step, self.max_step)
        self.theta = np.clip(self.theta + step, self.lower, self.upper)
        self.P = (self.P - np.outer(gain, Pphi)) / self.forgetting

    def invert(self, y: float) -> float:
        """The x for which the corrected map gives y."""
        return float((y - self.theta[0]) / self.theta[1])


@dataclass(frozen=True)
class LocalCorrection:
    """Kernel (GP) regression of residuals r(x) near the x already seen, with forgetting.

    Prior: r ~ GP(0, Σ_k sd_k² · exp(−(x − x')² / 2·length_k²)) over `scales` = ((length, sd),
    ...): a broad scale for a change of shape across x, a short one for steps. An observation
    `age` updates old has variance noise_sd² / forgetting^age, so old notes count less and a
    drifting world is followed. Residuals are clipped to ±`max_residual` before they enter, so
    one odd note moves the correction by a bounded amount.
    """

    scales: tuple[tuple[float, float], ...]
    noise_sd: float
    forgetting: float
    max_residual: float

    @property
    def prior_sd(self) -> float:
        """Spread of r where nothing has been observed."""
        return float(np.sqrt(sum(sd**2 for _, sd in self.scales)))

    def posterior(self, x: npt.ArrayLike, residuals: npt.ArrayLike, age: npt.ArrayLike,
                  at: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Mean and standard deviation of r at `at` from residuals observed at `x`, `age` ago."""
        q = np.asarray(at, dtype=np.float64)
        xs = np.asarray(x, dtype=np.float64)
        if xs.size == 0:
            return np.zeros(q.shape), np.full(q.shape, self.prior_sd)
        r = np.clip(np.asarray(residuals, dtype=np.float64), -self.max_residual, self.max_residual)
        noise = self.noise_sd**2 / self.forgetting ** np.asarray(age, dtype=np.float64)
        L = np.linalg.cholesky(self._kernel(xs, xs) + np.diag(noise))
        alpha = solve_triangular(L.T, solve_triangular(L, r, lower=True), lower=False)
        cross = self._kernel(q.ravel(), xs)
        v = solve_triangular(L, cross.T, lower=True)
        var = np.maximum(self.prior_sd**2 - np.sum(v * v, axis=0), 0.0)
        return (cross @ alpha).reshape(q.shape), np.sqrt(var).reshape(q.shape)

    def _kernel(self, a: FloatArray, b: FloatArray) -> FloatArray:
        d2 = (a[:, None] - b[None, :]) ** 2
        k = sum(sd**2 * np.exp(-0.5 * d2 / length**2) for length, sd in self.scales)
        return np.asarray(k, dtype=np.float64)
