"""Closing the loop while playing: online correction of the planner's model.

After each note the MIDI the piano reported is compared with the prediction, and two small
linear corrections are updated by recursive least squares with forgetting:

    played on-velocity ≈ a + b · predicted on-velocity
    observed lead (motion start → note-on) ≈ c + d · predicted lead

A different piano (velocity curve) or a finger whose stiffness drifted mostly scales and
shifts these maps, so two parameters each are enough to converge within a phrase. Steps are
bounded per update and the parameters clamped, so one odd note cannot throw the model off.
The planner inverts the corrected map for the next note: predicted = (target − a) / b.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

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

    def predict(self, x: float) -> float:
        return float(self.theta[0] + self.theta[1] * x)

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


@dataclass
class OnlineAdapter:
    """The planner's online corrections of loudness and lead, with their history."""

    velocity: RLS2 = field(default_factory=lambda: RLS2.prior(
        offset_sd=3.0, gain_sd=0.3, max_step=(2.0, 0.15), bounds=((-30.0, 30.0), (0.3, 3.0)),
        forgetting=0.97))
    lead: RLS2 = field(default_factory=lambda: RLS2.prior(
        offset_sd=0.05, gain_sd=0.2, max_step=(0.05, 0.1), bounds=((-0.5, 0.5), (0.5, 2.0)),
        forgetting=0.97))
    velocity_noise_var: float = 1.0  # MIDI quantisation and the piano's own scatter
    lead_noise_var: float = 1e-4  # ~10 ms
    history: list[dict[str, Any]] = field(default_factory=list)

    def model_target(self, target_velocity: float) -> float:
        """What the uncorrected model must predict so the corrected map gives the target."""
        return self.velocity.invert(target_velocity)

    def corrected_velocity(self, predicted: float) -> float:
        return self.velocity.predict(predicted)

    def corrected_lead(self, predicted_lead_s: float) -> float:
        return self.lead.predict(predicted_lead_s)

    def observe(self, note_index: int, predicted_velocity: float, predicted_lead_s: float,
                played_velocity: float | None, observed_lead_s: float | None) -> None:
        """Update both maps from one played note (a silent note counts as on-velocity 0)."""
        y = 0.0 if played_velocity is None else float(played_velocity)
        self.velocity.update(predicted_velocity, y, self.velocity_noise_var)
        if observed_lead_s is not None and np.isfinite(observed_lead_s):
            self.lead.update(predicted_lead_s, float(observed_lead_s), self.lead_noise_var)
        self.history.append({
            "note_index": note_index,
            "predicted_velocity": predicted_velocity,
            "played_velocity": played_velocity,
            "predicted_lead_s": predicted_lead_s,
            "observed_lead_s": observed_lead_s,
            "velocity_offset": float(self.velocity.theta[0]),
            "velocity_gain": float(self.velocity.theta[1]),
            "lead_offset_s": float(self.lead.theta[0]),
            "lead_gain": float(self.lead.theta[1]),
        })

    def state(self) -> dict[str, float]:
        return {
            "velocity_offset": float(self.velocity.theta[0]),
            "velocity_gain": float(self.velocity.theta[1]),
            "lead_offset_s": float(self.lead.theta[0]),
            "lead_gain": float(self.lead.theta[1]),
        }
