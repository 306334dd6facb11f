"""The one information criterion of the grey-box fitter, on a scale a scientist can read.

A model's misfit is mostly systematic (a missing effect leaves a smooth error of tens to
hundreds of µm), not the µm mocap noise; a χ² that divides mm residuals by µm noise makes
every difference look like 10¹⁰ and means nothing. Here the error of each channel is what it
is: a Gaussian likelihood whose variance σ² = noise² + systematic² is estimated from the
residuals (the profile likelihood, −2 log L = n·ln(RSS/n) per channel, floored at the noise
level). And a residual that is smooth along a keystroke does not hold one independent sample
per frame: each channel counts its effective number of samples n/τ, with τ the integrated
autocorrelation time of the reference model's residual (`noise.autocorrelation_time`; 1 for
MIDI outcomes, one per keystroke).

    IC = Σ_c (n_c/τ_c)·ln(max(RSS_c/n_c, noise_c²)) + k·ln(Σ_c n_c/τ_c)

(BIC's penalty on the effective sample size). ΔIC between two models fitted to the same
keystrokes with the same reference τ reads like an ordinary ΔBIC: above 10 is strong evidence.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pianobot.analysis.greybox.noise import autocorrelation_time

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Criterion:
    """The information criterion with fixed effective sample sizes and noise floors per channel."""

    n_eff: Mapping[str, float]  # channel -> effective independent samples
    noise: Mapping[str, float]  # channel -> noise level (floor of the error variance)

    @classmethod
    def of(cls, channels: Mapping[str, FloatArray], keystroke: Mapping[str, npt.NDArray[np.intp]],
           frame: Mapping[str, npt.NDArray[np.intp]], noise: Mapping[str, float]) -> Criterion:
        """Effective sample sizes from a reference fit's residuals (per channel, in natural
        units, with each residual's keystroke row and frame index)."""
        n_eff: dict[str, float] = {}
        for c, values in channels.items():
            if values.size == 0:
                continue
            frames = frame[c]
            if frames.size and frames.max() > 0:  # a time series per keystroke
                rows = keystroke[c]
                _, row = np.unique(rows, return_inverse=True)
                grid = np.full((int(row.max()) + 1, int(frames.max()) + 1), np.nan)
                grid[row, frames] = values
                tau = autocorrelation_time(grid)
            else:
                tau = 1.0
            n_eff[c] = values.size / tau
        return cls(n_eff, dict(noise))

    @property
    def n_total(self) -> float:
        return float(sum(self.n_eff.values()))

    def value(self, channels: Mapping[str, FloatArray], n_params: int) -> float:
        """IC of residuals (per channel, natural units) of a model with `n_params` free numbers."""
        total = 0.0
        for c, n_eff in self.n_eff.items():
            values = channels.get(c)
            if values is None or values.size == 0:
                continue
            floor = self.noise.get(c, 0.0) ** 2
            variance = max(float(np.mean(values**2)), floor, 1e-300)
            total += n_eff * math.log(variance)
        return total + n_params * math.log(max(self.n_total, 1.0))

    def log_likelihood_ratio(self, better: Mapping[str, FloatArray], worse: Mapping[str, FloatArray]) -> float:
        """2·ln(L_better/L_worse) on the effective sample sizes (no parameter penalty)."""
        return self.value(worse, 0) - self.value(better, 0)
