"""What discovery reports: each iteration's judgement, the measured checks, the verdict.

Units: positions in the JSON are metres with a millimetre copy (`*_mm`) for reading; every text
line and table in the report uses mm. The held-out gap ratio is before/after.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from pianobot.analysis.discover.decide import Rule, Verdict
from pianobot.analysis.discover.gap import Gap
from pianobot.analysis.discover.localise import Localisation
from pianobot.analysis.discover.measured import MeasuredCheck
from pianobot.analysis.discover.sparse import Proposal
from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.analysis.greybox.prediction import Prediction
from pianobot.physics.model import KeystrokeModel


@dataclass(frozen=True)
class Iteration:
    """One round: the current model's held-out gap and localisation, every candidate judged."""

    index: int
    gap_before: Gap
    before: Localisation
    verdicts: tuple[Verdict, ...]
    accepted: Verdict | None
    after: Localisation | None
    explainable: bool  # the current model's held-out error is above the noise
    proposals: tuple[Proposal, ...] = ()  # the residual search, when nothing was accepted
    window: str = "press"  # trajectories modelled until lift-off, or through the release
    # Effects accepted in earlier rounds and dropped after this round's acceptance: each judged
    # as a candidate added back to the model refitted without it (its `gap_before` is the
    # held-out gap of the model kept).
    dropped: tuple[Verdict, ...] = ()

    @property
    def gap_after(self) -> Gap:
        """The held-out gap of the model this round leaves (after any effect it dropped)."""
        if self.dropped:
            return self.dropped[-1].gap_before
        return self.accepted.gap_after if self.accepted else self.gap_before

    @property
    def heading(self) -> str:
        """"Iteration n", saying when it judged the release (the model window past lift-off)."""
        return f"Iteration {self.index + 1}" + (" (the release, past lift-off)" if self.window == "release" else "")

    def to_dict(self) -> dict[str, Any]:
        return {
            "index": self.index,
            "window": self.window,
            "accepted_effect": self.accepted.effect if self.accepted else None,
            "accepted_form": self.accepted.form if self.accepted else None,
            "accepted_family": self.accepted.family if self.accepted else None,
            "gap_before": self.gap_before.to_dict(),
            "gap_after": self.gap_after.to_dict(),
            "dropped": [{**v.to_dict(), "text": dropped_text(v)} for v in self.dropped],
            "explainable": self.explainable,
            "candidates": [v.to_dict() for v in self.verdicts],
            "residual_search": [{"term": p.term, "family": p.family, "coefficient": p.coefficient, "share": p.share}
                                for p in self.proposals],
            "localisation_before": self.before.to_dict(),
            "localisation_after": None if self.after is None else self.after.to_dict(),
        }


@dataclass(frozen=True)
class ReleaseView:
    """The held-out keystrokes modelled through the release (past lift-off): the model that
    entered the release rounds and the one that left them."""

    before: Prediction
    after: Prediction


@dataclass(frozen=True)
class DiscoveryResult:
    """Everything discovery found, with the model it ends with."""

    mode: str  # "trajectories" (measured arm drives the model) | "midi" (commanded presses)
    iterations: tuple[Iteration, ...]
    findings: tuple[MeasuredCheck, ...]  # checks against the measurements themselves (arm, clock, readout)
    start_model: KeystrokeModel
    base_model: KeystrokeModel  # the start model with its base parameters fitted
    final_model: KeystrokeModel
    base_params: dict[str, float]
    base_on_bounds: tuple[str, ...]
    verdict: str
    explained: bool
    rule: Rule
    n_train: int
    n_held_out: int
    held_out: KeystrokeBatch
    predictions_before: Prediction  # held-out, base model
    predictions_after: Prediction  # held-out, final model
    base_holdout_rms_x2_m: float = math.nan  # as identify reports it (x2 only, offsets profiled)
    unexplained: Proposal | None = None
    notes: tuple[str, ...] = ()
    seconds: float = math.nan
    timings: dict[str, float] = field(default_factory=dict)
    release: ReleaseView | None = None  # when the release was judged (fingertips tracked off the key)

    @property
    def accepted(self) -> tuple[Verdict, ...]:
        """The accepted effects the final model holds, in the order they were found (an effect a
        later round dropped is not among them)."""
        return in_model(self.iterations)

    @property
    def dropped(self) -> tuple[Verdict, ...]:
        return tuple(v for it in self.iterations for v in it.dropped)

    @property
    def accepted_effects(self) -> tuple[str, ...]:
        """Accepted effects in the order they were found."""
        return tuple(v.effect for v in self.accepted)

    @property
    def measured_effects(self) -> tuple[str, ...]:
        """Effects established against the measurements (arm, clock, readout) and in the model."""
        return tuple(f.effect for f in self.findings if f.accepted)

    @property
    def press_iterations(self) -> tuple[Iteration, ...]:
        """The iterations judged until lift-off (the release ones model a longer window: their
        gaps are not comparable with these)."""
        return tuple(it for it in self.iterations if it.window == "press")

    @property
    def gap_before(self) -> Gap:
        return self.iterations[0].gap_before

    @property
    def gap_after(self) -> Gap:
        return self.press_iterations[-1].gap_after

    @property
    def decision_line(self) -> str:
        return decision_line(self)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (the `--json` output)."""
        return {
            "mode": self.mode,
            "verdict": self.verdict,
            "explained": self.explained,
            "decision": self.decision_line,
            "accepted_effects": list(self.accepted_effects),
            "accepted": [{"effect": v.effect, "form": v.form, "family": v.family} for v in self.accepted],
            "dropped": [{"effect": v.effect, "form": v.form, "family": v.family, "text": dropped_text(v)}
                        for v in self.dropped],
            "measured": [f.to_dict() for f in self.findings],
            "measured_effects": list(self.measured_effects),
            "unexplained_term": None if self.unexplained is None else {
                "term": self.unexplained.term, "family": self.unexplained.family, "share": self.unexplained.share},
            "base_params": self.base_params,
            "base_on_bounds": list(self.base_on_bounds),
            "base_holdout_rms_x2_m": self.base_holdout_rms_x2_m,
            "gap_before": self.gap_before.to_dict(),
            "gap_after": self.gap_after.to_dict(),
            "rule": self.rule.describe(),
            "n_train": self.n_train,
            "n_held_out": self.n_held_out,
            "notes": list(self.notes),
            "seconds": self.seconds,
            "iterations": [it.to_dict() for it in self.iterations],
            "final_model": self.final_model.to_dict(),
        }


#: Display units of parameter-name suffixes (name suffix -> scale, unit); the first match wins.
_DISPLAY_UNITS: tuple[tuple[str, float, str], ...] = (
    ("_per_m", 1e-3, "1/mm"), ("_nspm", 1.0, "N·s/m"), ("_npm", 1.0, "N/m"), ("_mps", 1e3, "mm/s"),
    ("_m", 1e3, "mm"), ("_s", 1e3, "ms"), ("_n", 1.0, "N"),
)


def params_text(v: Verdict) -> str:
    """A candidate's parameters with 95 % intervals in display units (lengths in mm, times in ms,
    speeds in mm/s, forces in N), the unit suffix dropped from the name, those that ended on a
    bound flagged: one text for the decision line and the report's tables."""
    parts = []
    for name, value in v.params.items():
        lo, hi = v.intervals.get(name, (math.nan, math.nan))
        short = name.split(".", 1)[1]
        scale, unit = 1.0, ""
        for suffix, factor, label in _DISPLAY_UNITS:
            if short.endswith(suffix):
                short, scale, unit = short[: -len(suffix)], factor, " " + label
                break
        ci = f" [{scale * lo:.3g}, {scale * hi:.3g}]" if math.isfinite(lo) and math.isfinite(hi) else ""
        flag = " (on bound)" if name in v.on_bounds else ""
        parts.append(f"{short} = {scale * value:.3g}{unit}{ci}{flag}")
    return ", ".join(parts)


def in_model(iterations: Sequence[Iteration]) -> tuple[Verdict, ...]:
    """The accepted effects still in the model after `iterations`, in the order found."""
    kept: list[Verdict] = []
    for it in iterations:
        if it.accepted:
            kept.append(it.accepted)
        gone = {v.label for v in it.dropped}
        kept = [v for v in kept if v.label not in gone or v is it.accepted]
    return tuple(kept)


def dropped_text(v: Verdict) -> str:
    """Why an effect accepted earlier left the model."""
    return (f"{v.label} dropped: no longer needed with the effects found after it (refitted without it: "
            f"ΔIC {v.delta_ic:.1f}, held-out {v.gap_before.text()} without it, {v.gap_after.text()} with it)")


def decision_line(result: DiscoveryResult) -> str:
    """One line per accepted effect: parameters with 95 % intervals, held-out gap before → after."""
    lines = []
    for v in result.accepted:
        params = params_text(v)
        ratio = "to the noise floor" if not math.isfinite(v.ratio) else f"{v.ratio:.1f}×"
        lines.append(f"Missing effect: {v.label}" + (f" ({params})" if params else "")
                     + f"; held-out {v.gap_before.text()} → {v.gap_after.text()} ({ratio}); ΔIC {v.delta_ic:.0f}")
    lines += [f"Dropped: {dropped_text(v)}" for v in result.dropped]
    return "\n".join(lines) if lines else "No missing effect found."


def verdict_text(iterations: Sequence[Iteration], findings: Sequence[MeasuredCheck], final: Gap,
                 unexplained: Proposal | None, explainable: bool, worst: Sequence[str]) -> tuple[str, bool]:
    """The closing sentence, and whether what is left is at the noise level."""
    after_lift_off = {it.accepted.label for it in iterations if it.accepted and it.window == "release"}
    accepted = [v.label + (" (seen after lift-off)" if v.label in after_lift_off else "") for v in in_model(iterations)]
    text = ("missing effects found: " + ", ".join(accepted)) if accepted else "no missing effect found"
    dropped = [v.label for it in iterations for v in it.dropped]
    if dropped:
        text += f" ({', '.join(dropped)}, accepted first, dropped: not needed once the later effects were in)"
    measured = [f.effect for f in findings if f.accepted]
    if measured:
        text += "; measured on the set-up: " + ", ".join(measured)
    if not explainable:
        return text + f"; the remaining held-out error ({final.text()}) is at the noise level (explained)", True
    where = f" in stages {', '.join(worst)}" if worst else ""
    hint = ""
    if unexplained is not None:
        family = f", family {unexplained.family}" if unexplained.family else ""
        hint = f"; best-supported residual term: {unexplained.term}{family}"
    return text + f"; an unexplained discrepancy remains ({final.text()}){where}{hint}", False
