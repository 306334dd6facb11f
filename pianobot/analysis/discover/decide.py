"""The acceptance rule: when is a candidate effect real rather than a better fit to noise?

A candidate (the current model plus one effect, refitted jointly) is accepted only when all hold:

1. **evidence**: ΔIC (current − candidate, on the training keystrokes, `greybox.criterion`)
   exceeds `ic_margin`: strong evidence on a likelihood whose error is the model's actual
   systematic-plus-noise error and whose sample size is the effective one;
2. **something to explain**: the current model's held-out systematic error is above the noise
   (`floor_sigmas` × σ with trajectories; a MIDI gap above the rounding floor);
3. **held-out gap shrink**: the candidate removes at least `min_shrink` of it on keystrokes it
   was not fitted to;
4. **consistency**: of the held-out keystrokes it changes, at least `min_consistency` improve
   (one keystroke cannot carry a discovery);
5. **size**: the 95 % interval of the effect's size parameter excludes its "off" value
   (switch-like effects without parameters are judged by 1–4 alone).

Among the candidates that pass, the largest ΔIC wins; a simpler one (fewer parameters) within
`nested_tolerance` of it is preferred: of nested alternatives the simpler explains as well.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from pianobot.analysis.discover.candidates import family_of
from pianobot.analysis.discover.gap import Gap, above_noise, consistency, measures, score


@dataclass(frozen=True)
class Rule:
    """Thresholds of the acceptance rule (stated in the report)."""

    ic_margin: float = 10.0
    floor_sigmas: float = 1.0
    min_shrink: float = 0.3
    min_consistency: float = 0.7
    nested_tolerance: float = 10.0

    def describe(self) -> str:
        return (f"ΔIC > {self.ic_margin:g}; held-out systematic error above {self.floor_sigmas:g} σ of noise; "
                f"shrinks by ≥ {100 * self.min_shrink:.0f} %; ≥ {100 * self.min_consistency:.0f} % of the held-out "
                "keystrokes it changes improve; the effect's size interval excludes 'off'")


@dataclass(frozen=True)
class Verdict:
    """One candidate judged (JSON-ready figures; the fitted model lives in the search)."""

    label: str
    effect: str
    form: str
    params: dict[str, float]
    intervals: dict[str, tuple[float, float]]
    on_bounds: tuple[str, ...]
    delta_ic: float
    gap_before: Gap
    gap_after: Gap
    shrink: float  # 1 − score: fraction of the held-out gap removed
    consistency: float
    size_excludes_off: bool
    joint: bool
    measure: str = ""  # the held-out measure the shrink is read on
    status: str = "pending"
    reasons: tuple[str, ...] = field(default_factory=tuple)

    @property
    def family(self) -> str | None:
        return family_of(self.effect)

    @property
    def n_params(self) -> int:
        return len(self.params)

    @property
    def ratio(self) -> float:
        """Held-out gap before / after (∞ when the gap vanished)."""
        after = 1.0 - self.shrink
        return 1.0 / after if after > 0 else math.inf

    def to_dict(self) -> dict[str, Any]:
        return {
            "label": self.label, "effect": self.effect, "form": self.form, "family": self.family,
            "params": {k: {"value": v, "ci95": list(self.intervals.get(k, (math.nan, math.nan))),
                           "on_bound": k in self.on_bounds} for k, v in self.params.items()},
            "delta_ic": self.delta_ic, "gap_before": self.gap_before.to_dict(), "gap_after": self.gap_after.to_dict(),
            "measures": {k: list(v) for k, v in measures(self.gap_after, self.gap_before).items()},
            "shrink": self.shrink, "ratio": self.ratio, "measure": self.measure, "consistency": self.consistency,
            "size_excludes_off": self.size_excludes_off, "joint_fit": self.joint, "status": self.status,
            "reasons": list(self.reasons),
        }


def something_to_explain(gap: Gap, rule: Rule) -> bool:
    """True when the held-out gap is above the noise (module docstring, condition 2)."""
    if math.isfinite(gap.position_m):
        return gap.position_m > rule.floor_sigmas * gap.sigma_m
    return bool(above_noise(gap))


def verdict(label: str, effect: str, form: str, params: dict[str, float], intervals: dict[str, tuple[float, float]],
            on_bounds: tuple[str, ...], delta_ic: float, before: Gap, after: Gap, size_excludes_off: bool,
            joint: bool) -> Verdict:
    """A candidate's figures, not yet judged."""
    s, measure = score(after, before)
    return Verdict(label, effect, form, params, intervals, on_bounds, delta_ic, before, after,
                   1.0 - s if math.isfinite(s) else 0.0, consistency(after, before, measure), size_excludes_off,
                   joint, measure)


def percent_text(percent: float, limit: float) -> str:
    """A percentage in whole percents (an int: never "-0"), or to a tenth where it is below
    `limit` and whole percents would round it up to the limit ("29.6 % < 30 %", not "30 % < 30 %").
    The tables use it too, so a cell never reads "30 %" beside a reason "29.7 % < 30 %"."""
    whole = round(percent)
    return str(whole) if whole < limit or percent >= limit else f"{math.floor(10 * percent) / 10:.1f}"


def judge(v: Verdict, rule: Rule, explainable: bool) -> Verdict:
    """Mark a candidate as passing or rejected, with every reason it fails."""
    reasons = []
    if not v.delta_ic > rule.ic_margin:
        reasons.append(f"ΔIC {v.delta_ic:.1f} ≤ {rule.ic_margin:g}")
    if not explainable:
        reasons.append("held-out error is at the noise level")
    if not v.shrink >= rule.min_shrink:
        change = 100 * v.shrink
        reasons.append(f"held-out gap grows {percent_text(-change, math.inf)} %" if round(change) < 0
                       else f"held-out gap shrinks {percent_text(change, 100 * rule.min_shrink)} % < "
                            f"{100 * rule.min_shrink:g} %")
    if not v.consistency >= rule.min_consistency:
        reasons.append(f"improves {percent_text(100 * v.consistency, 100 * rule.min_consistency)} % of changed "
                       f"held-out keystrokes < {100 * rule.min_consistency:g} %")
    if not v.size_excludes_off:
        reasons.append("size interval includes 'off'")
    return replace(v, status="passes" if not reasons else "rejected", reasons=tuple(reasons))


def choose(verdicts: Sequence[Verdict], rule: Rule, explainable: bool) -> tuple[Verdict | None, list[Verdict]]:
    """Judge every candidate; (accepted or None, all judged, best ΔIC first)."""
    judged = sorted((judge(v, rule, explainable) for v in verdicts), key=lambda v: -v.delta_ic)
    passing = [v for v in judged if v.status == "passes"]
    if not passing:
        return None, judged
    best = passing[0]
    close = [v for v in passing if v.delta_ic >= best.delta_ic - rule.nested_tolerance]
    chosen = min(close, key=lambda v: (v.n_params, -v.delta_ic))
    return replace(chosen, status="accepted"), [replace(v, status="accepted") if v is chosen else v for v in judged]
