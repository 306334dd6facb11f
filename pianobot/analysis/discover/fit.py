"""A small bounded output-error fitter with confidence intervals and an information criterion.

Discovery fits each candidate (base parameters + one effect's parameters) by simulation error.
The residual function is supplied by the caller and already divided by the noise level, so the
sum of squares is a χ² and ΔBIC between two fits is Δχ² − Δk·ln n.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class ParamSpec:
    """One free parameter: start value, bounds, and the value meaning "effect off"."""

    name: str
    start: float
    lower: float
    upper: float
    off: float | None = None  # None for base parameters (no "off")
    log: bool = False  # fit in log space (positive scale-like parameters)

    def to_internal(self, value: float) -> float:
        """Value → optimiser coordinate."""
        return float(np.log(value)) if self.log else float(value)

    def from_internal(self, value: float) -> float:
        """Optimiser coordinate → value."""
        return float(np.exp(value)) if self.log else float(value)


@dataclass(frozen=True)
class FitResult:
    """A least-squares fit: values, 95 % intervals, χ², BIC."""

    names: tuple[str, ...]
    values: tuple[float, ...]
    lower_ci: tuple[float, ...]
    upper_ci: tuple[float, ...]
    chi2: float
    n: int
    bic: float
    success: bool

    def value(self, name: str) -> float:
        """The fitted value of one parameter."""
        return self.values[self.names.index(name)]

    def as_dict(self) -> dict[str, float]:
        """Name → fitted value."""
        return dict(zip(self.names, self.values, strict=True))

    def excludes(self, name: str, off: float) -> bool:
        """True when the 95 % interval of `name` lies entirely on one side of `off`."""
        i = self.names.index(name)
        return bool(self.lower_ci[i] > off or self.upper_ci[i] < off)


def bic(chi2: float, n_params: int, n: int) -> float:
    """Bayesian information criterion for a χ² (noise already divided out)."""
    return float(chi2 + n_params * np.log(max(n, 1)))


def fit(
    specs: Sequence[ParamSpec],
    residuals: Callable[[dict[str, float]], FloatArray],
    max_nfev: int = 60,
    diff_step: float = 1e-3,
    tol: float = 1e-4,
) -> FitResult:
    """Minimise the sum of squared residuals over the parameters within their bounds.

    Intervals come from the Gauss–Newton covariance (JᵀJ)⁻¹, scaled by the reduced χ² when the
    fit is worse than the noise (so a misfit widens the intervals instead of hiding).
    """
    specs = tuple(specs)
    names = tuple(s.name for s in specs)

    def internal_residuals(theta: FloatArray) -> FloatArray:
        values = {s.name: s.from_internal(t) for s, t in zip(specs, theta, strict=True)}
        r = np.asarray(residuals(values), dtype=np.float64)
        return np.where(np.isfinite(r), r, 0.0)

    lower = np.array([s.to_internal(s.lower) for s in specs])
    upper = np.array([s.to_internal(s.upper) for s in specs])
    start = np.clip(np.array([s.to_internal(s.start) for s in specs]), lower, upper)
    if not specs:
        r = internal_residuals(start)
        chi2 = float(r @ r)
        return FitResult((), (), (), (), chi2, r.size, bic(chi2, 0, r.size), True)
    result = least_squares(
        internal_residuals,
        start,
        bounds=(lower, upper),
        x_scale="jac",
        diff_step=diff_step,
        max_nfev=max_nfev,
        method="trf",
        ftol=tol,
        xtol=tol,
        gtol=tol,
    )
    r = result.fun
    n = int(r.size)
    chi2 = float(r @ r)
    k = len(specs)
    jac = np.asarray(result.jac, dtype=np.float64)
    scale = max(1.0, chi2 / max(n - k, 1))
    try:
        cov = np.linalg.pinv(jac.T @ jac) * scale
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    except np.linalg.LinAlgError:
        std = np.full(k, np.inf)
    theta = result.x
    values, lo, hi = [], [], []
    for s, t, sd in zip(specs, theta, std, strict=True):
        values.append(s.from_internal(t))
        lo.append(s.from_internal(t - 1.96 * sd))
        hi.append(s.from_internal(t + 1.96 * sd))
    return FitResult(
        names, tuple(values), tuple(lo), tuple(hi), chi2, n, bic(chi2, k, n), bool(result.success)
    )
