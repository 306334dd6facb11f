"""What discovery reports: one iteration's judgement, the whole result, the decision line."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pianobot.analysis.discover import params as dp
from pianobot.analysis.discover.data import Keystroke, Prediction
from pianobot.analysis.discover.decide import Candidate, family_of
from pianobot.analysis.discover.localise import Localisation
from pianobot.analysis.discover.sparse import Proposal
from pianobot.physics.model import KeystrokeModel


@dataclass(frozen=True)
class Iteration:
    """One round: localisation before, every candidate judged, the accepted one (or none)."""

    index: int
    before: Localisation
    after: Localisation | None
    candidates: tuple[Candidate, ...]
    accepted: Candidate | None
    threshold: float
    bootstrap_delta_bic: tuple[float, ...]
    proposals: tuple[Proposal, ...]

    def to_dict(self) -> dict[str, Any]:
        """The JSON form (`accepted_effect`, `candidates`, `gap_before`, `gap_after`, ...)."""
        after = self.after if self.after is not None else self.before
        return {
            "index": self.index,
            "accepted_effect": self.accepted.effect if self.accepted else None,
            "accepted_family": family_of(self.accepted.effect) if self.accepted else None,
            "gap_before": self.before.gap.to_dict(),
            "gap_after": after.gap.to_dict(),
            "threshold_delta_bic": self.threshold,
            "bootstrap_delta_bic": list(self.bootstrap_delta_bic),
            "candidates": [c.to_dict() for c in self.candidates],
            "sparse_proposals": [
                {"term": p.term, "family": p.family, "coefficient": p.coefficient, "share": p.share}
                for p in self.proposals
            ],
            "localisation_before": self.before.to_dict(),
            "localisation_after": after.to_dict(),
        }


@dataclass(frozen=True)
class DiscoveryResult:
    """Everything discovery found, with the model it ends with."""

    iterations: tuple[Iteration, ...]
    start_model: KeystrokeModel
    base_model: KeystrokeModel  # the start model with its base parameters refit
    final_model: KeystrokeModel
    verdict: str
    explained: bool
    decision_line: str
    n_train: int
    n_held_out: int
    held_out_ids: tuple[str, ...]
    predictions_before: tuple[Prediction, ...] = ()  # held-out, base model
    predictions_after: tuple[Prediction, ...] = ()  # held-out, final model
    held_out: tuple[Keystroke, ...] = ()
    notes: tuple[str, ...] = ()  # assumptions made for parameters the data do not record

    @property
    def accepted_effects(self) -> tuple[str, ...]:
        """Accepted effects in the order they were found."""
        return tuple(it.accepted.effect for it in self.iterations if it.accepted)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (the `--json` output)."""
        return {
            "verdict": self.verdict,
            "explained": self.explained,
            "decision": self.decision_line,
            "accepted_effects": list(self.accepted_effects),
            "n_train": self.n_train,
            "n_held_out": self.n_held_out,
            "notes": list(self.notes),
            "iterations": [it.to_dict() for it in self.iterations],
            "final_model": dp.model_to_dict(self.final_model),
        }


def verdict(
    iterations: Sequence[Iteration],
    final: Localisation,
    noise_lag1: float = 0.5,
    noise_fraction: float = 1.0,
) -> tuple[str, bool]:
    """The closing sentence and whether the remaining held-out residual looks like noise.

    It does when its systematic part is within `noise_fraction` of the noise level, or within
    three times that and white (low lag-1 autocorrelation); otherwise the worst phases are named.
    """
    accepted = [it.accepted.effect for it in iterations if it.accepted]
    found = (
        ("missing effects found: " + ", ".join(accepted)) if accepted else "no missing effect found"
    )
    lags = [row["lag1"] for row in final.phases if np.isfinite(row["lag1"])]
    noisy_shape = not lags or float(np.median(lags)) < noise_lag1
    g = final.gap
    if np.isfinite(g.position_m):
        # Within the noise level, or a little above it but white (no structure left to model).
        sigma = max(g.sigma_m, 1e-12)
        small = g.position_m <= noise_fraction * sigma or (
            g.position_m <= 3.0 * noise_fraction * sigma and noisy_shape
        )
    else:
        small = not np.isfinite(g.on_velocity) or g.on_velocity <= 1.0
    if small:
        return f"{found}; the remaining residual looks like noise (explained)", True
    phases = final.worst_phases() or ["outcomes"]
    return f"{found}; unexplained discrepancy remains in phases {', '.join(phases)}", False


def decision_line(iterations: Sequence[Iteration]) -> str:
    """One line per accepted effect: parameters ± half-width, held-out gap before → after."""
    parts = []
    for it in iterations:
        if it.accepted is None or it.after is None:
            continue
        c = it.accepted
        params = ", ".join(
            f"{name.split('.', 1)[1]} = {dp.format_value(name, c.fit.value(name), c.fit, name)}"
            for name in c.effect_params
        )
        b, a = it.before.gap, it.after.gap
        text = f"Missing effect: {c.effect}" + (f", {params}" if params else "")
        if np.isfinite(c.gap_before):  # the position gap was above its noise floor
            shrink = f"{b.primary / a.primary:.1f}×" if a.primary > 0 else "to the noise floor"
            unit, scale = ("mm", 1e3) if b.primary_name == "position_m" else ("", 1.0)
            what = "RMS" if unit else "MIDI velocity RMS"
            text += (
                f"; held-out systematic {what} {b.primary * scale:.3g} → "
                f"{a.primary * scale:.3g}{(' ' + unit) if unit else ''} ({shrink})"
            )
        if (
            np.isfinite(b.on_velocity)
            and np.isfinite(a.on_velocity)
            and b.primary_name == "position_m"
        ):
            text += f"; MIDI velocity RMS {b.on_velocity:.2g} → {a.on_velocity:.2g}"
        parts.append(text)
    return "\n".join(parts) if parts else "No missing effect found."
