"""The acceptance rule: when is a candidate effect real rather than a better fit to noise?

A candidate is accepted only when all of these hold:

1. ΔBIC (base − candidate, on training keystrokes) exceeds a threshold: a fixed margin, raised to
   the largest ΔBIC a parametric bootstrap of the fitted base model produced (data simulated
   without the effect, so whatever ΔBIC the candidate wins there is what noise alone can buy);
2. the held-out systematic error shrinks by at least `min_gap_reduction` (a fraction);
3. the 95 % interval of at least one of its parameters excludes that parameter's "off" value.

Among the candidates that pass, a simpler one (fewer parameters) within `nested_tolerance` of
the best ΔBIC is preferred: of nested families the simpler member explains the data as well.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from pianobot.analysis.discover.fit import FitResult

# Effects that are alternative explanations of the same observation; naming any member counts
# as naming the family (e.g. a trapezoid input and a lagging arm both delay the key).
FAMILIES: dict[str, str] = {
    "contact": "contact",
    "adhesion": "contact",
    "keybed": "key_stop",
    "letoff": "key_stop",
    "key_preload": "key_action",
    "key_friction": "key_action",
    "finger_stiffening": "finger",
    "stiffness_drift": "finger",
    "arm_lag": "arm",
    "arm_acceleration": "arm",
    "velocity_curve": "piano",
    "mocap_delay": "mocap",
}


def family_of(effect: str | None) -> str | None:
    """The family an effect belongs to (itself when unlisted)."""
    return None if effect is None else FAMILIES.get(effect, effect)


@dataclass(frozen=True)
class DecisionRule:
    """Thresholds of the acceptance rule (the stated fractions are part of the report)."""

    bic_margin: float = 10.0
    min_gap_reduction: float = 0.1
    nested_tolerance: float = 10.0
    bootstrap_factor: float = 2.0  # threshold ≥ factor × largest bootstrap ΔBIC

    def threshold(self, bootstrap_delta_bic: Sequence[float] = ()) -> float:
        """The ΔBIC a candidate must beat, given null ΔBICs from the bootstrap."""
        null = [x for x in bootstrap_delta_bic if np.isfinite(x)]
        return max(self.bic_margin, self.bootstrap_factor * max(null, default=0.0))


@dataclass(frozen=True)
class Candidate:
    """One candidate effect fitted jointly with the base parameters."""

    effect: str
    fit: FitResult
    effect_params: tuple[str, ...]
    off_values: tuple[float, ...]
    delta_bic: float
    gap_before: float  # held-out primary gap of the base model
    gap_after: float  # held-out primary gap with this effect
    proposed_by: tuple[str, ...] = ()  # e.g. ("sparse",) when STLSQ pointed at it
    # Other held-out measures above their noise floor: (name, before, after), e.g. on-velocity.
    other_gaps: tuple[tuple[str, float, float], ...] = ()
    status: str = "pending"
    reasons: tuple[str, ...] = field(default_factory=tuple)

    @property
    def n_params(self) -> int:
        """How many effect parameters the candidate adds."""
        return len(self.effect_params)

    @property
    def gap_reduction(self) -> float:
        """Fraction of the held-out gap removed (negative when it grows).

        Over every measure above its noise floor (position, and MIDI velocity when recorded):
        the largest reduction counts, unless some measure grows by more than 10 % — an
        effect that fixes the sound but breaks the motion is not an explanation.
        """
        reductions = [
            1.0 - after / before
            for _, before, after in (("primary", self.gap_before, self.gap_after), *self.other_gaps)
            if np.isfinite(before) and before > 0 and np.isfinite(after)
        ]
        if not reductions:
            return 0.0
        worst = min(reductions)
        return float(worst if worst < -0.1 else max(reductions))

    @property
    def off_excluded(self) -> bool:
        """True when some effect parameter's interval excludes its "off" value.

        A switch without parameters (contact, arm_acceleration) has no interval: for it the
        information criterion and the held-out gap decide alone.
        """
        checks = [
            (name, off)
            for name, off in zip(self.effect_params, self.off_values, strict=True)
            if np.isfinite(off)
        ]
        if not checks:
            return True
        return any(self.fit.excludes(name, off) for name, off in checks)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready values."""
        params = {}
        for name in self.effect_params:
            i = self.fit.names.index(name)
            params[name] = {
                "value": self.fit.values[i],
                "ci95": [self.fit.lower_ci[i], self.fit.upper_ci[i]],
            }
        return {
            "effect": self.effect,
            "family": family_of(self.effect),
            "params": params,
            "delta_bic": self.delta_bic,
            "gap_before": self.gap_before,
            "gap_after": self.gap_after,
            "gap_reduction": self.gap_reduction,
            "other_gaps": [
                {"measure": name, "before": before, "after": after}
                for name, before, after in self.other_gaps
            ],
            "off_excluded": self.off_excluded,
            "proposed_by": list(self.proposed_by),
            "status": self.status,
            "reasons": list(self.reasons),
        }


def judge(candidate: Candidate, rule: DecisionRule, threshold: float) -> Candidate:
    """Mark a candidate as passing or rejected, with every reason it fails."""
    reasons = []
    if not candidate.delta_bic > threshold:
        reasons.append(f"ΔBIC {candidate.delta_bic:.1f} ≤ threshold {threshold:.1f}")
    if not candidate.gap_reduction >= rule.min_gap_reduction:
        reasons.append(
            f"held-out gap shrinks {100 * candidate.gap_reduction:.0f} % "
            f"< {100 * rule.min_gap_reduction:.0f} %"
        )
    if not candidate.off_excluded:
        reasons.append("parameter interval includes 'off'")
    status = "passes" if not reasons else "rejected"
    return replace(candidate, status=status, reasons=tuple(reasons))


def choose(
    candidates: Sequence[Candidate], rule: DecisionRule, threshold: float
) -> tuple[Candidate | None, list[Candidate]]:
    """Judge every candidate and pick the accepted one (or None).

    Returns:
        (accepted, all candidates judged, best ΔBIC first).
    """
    judged = sorted((judge(c, rule, threshold) for c in candidates), key=lambda c: -c.delta_bic)
    passing = [c for c in judged if c.status == "passes"]
    if not passing:
        return None, judged
    best = passing[0]
    close = [c for c in passing if c.delta_bic >= best.delta_bic - rule.nested_tolerance]
    chosen = min(close, key=lambda c: (c.n_params, -c.delta_bic))
    out = [replace(c, status="accepted") if c is chosen else c for c in judged]
    return replace(chosen, status="accepted"), out
