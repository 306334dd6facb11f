"""What `pianobot sweep --dry-run` shows: trial count, coverage, lab time, violations."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pianobot.durations import format_duration
from pianobot.plan.approach import as_specified, with_fast_approach
from pianobot.plan.envelope import Violation
from pianobot.plan.labtime import LabTime, lab_time
from pianobot.plan.trial import Trial, trial_columns
from pianobot.spec import PARAMETERS, ExperimentSpec, RigSpec, load_rig_for

_SHOWN_INDICES = 8


@dataclass(frozen=True)
class Coverage:
    """How a parameter is covered by a plan."""

    minimum: float
    maximum: float
    levels: int  # distinct values

    def to_dict(self) -> dict[str, float | int]:
        """Plain JSON-able dict."""
        return {"min": self.minimum, "max": self.maximum, "levels": self.levels}


@dataclass(frozen=True)
class ViolationGroup:
    """Violations of one rule on one parameter, with one example message."""

    severity: str
    rule: str
    parameter: str
    count: int
    indices: tuple[int, ...]  # the first few trial indices
    example: str

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able dict."""
        return {"severity": self.severity, "rule": self.rule, "parameter": self.parameter,
                "count": self.count, "indices": list(self.indices), "example": self.example}


@dataclass(frozen=True)
class PlanSummary:
    """A plan at a glance, before anything moves."""

    name: str
    finger: str
    rig: str
    mode: str
    order: str
    trial_count: int
    coverage: dict[str, Coverage]
    lab_time: LabTime
    violations: tuple[Violation, ...]
    approach: str = "as-specified"  # the spec's approach option (what `lab_time` is for)
    lab_time_by_approach: dict[str, LabTime] | None = None  # both options, for comparison

    @property
    def errors(self) -> int:
        """Number of error-severity violations (the plan is refused if > 0)."""
        return sum(v.severity == "error" for v in self.violations)

    @property
    def warnings(self) -> int:
        """Number of warnings."""
        return sum(v.severity == "warning" for v in self.violations)

    def groups(self) -> list[ViolationGroup]:
        """Violations grouped by severity, rule and parameter (errors first)."""
        grouped: dict[tuple[str, str, str], list[Violation]] = {}
        for v in self.violations:
            grouped.setdefault((v.severity, v.rule, v.parameter), []).append(v)
        return [
            ViolationGroup(sev, rule, param, len(vs),
                           tuple(v.index for v in vs[:_SHOWN_INDICES]), vs[0].message)
            for (sev, rule, param), vs in sorted(grouped.items(), key=lambda kv: kv[0][0] != "error")
        ]

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able dict (every violation listed, plus the groups)."""
        return {
            "name": self.name,
            "finger": self.finger,
            "rig": self.rig,
            "mode": self.mode,
            "order": self.order,
            "trials": self.trial_count,
            "coverage": {name: c.to_dict() for name, c in self.coverage.items()},
            "lab_time": self.lab_time.to_dict(),
            "approach": self.approach,
            "lab_time_by_approach": {k: v.to_dict() for k, v in (self.lab_time_by_approach or {}).items()},
            "errors": self.errors,
            "warnings": self.warnings,
            "violation_groups": [g.to_dict() for g in self.groups()],
            "violations": [v.to_dict() for v in self.violations],
        }

    def to_text(self) -> str:
        """A few lines for people: counts, a coverage table, time, grouped violations."""
        t = self.lab_time
        lines = [
            f"{self.name}: {self.trial_count} trials, {self.finger} finger, rig {self.rig}, "
            f"{self.mode} sweep, order {self.order}",
            f"lab time ≈ {format_duration(t.total_s)}: presses {format_duration(t.presses_s)}, "
            f"pauses {format_duration(t.pauses_s)}, vacuum settling {format_duration(t.vacuum_s)} "
            f"({_changes(t.vacuum_changes)}), key moves {format_duration(t.travel_s)} "
            f"({_changes(t.key_changes)})",
        ]
        both = self.lab_time_by_approach or {}
        if "as-specified" in both and "fast" in both:
            slow, fast = both["as-specified"].total_s, both["fast"].total_s
            ratio = f" ({fast / slow:.2f}×)" if slow > 0 else ""
            hint = "" if self.approach == "fast" else "; set `approach: fast` in the spec to use it"
            lines.append(f"approach {self.approach}: as-specified {format_duration(slow)}, "
                         f"fast approach {format_duration(fast)}{ratio}{hint}")
        lines.append(f"{'parameter':<20} {'min':>10} {'max':>10} {'levels':>7}")
        for name, c in self.coverage.items():
            unit = PARAMETERS[name].unit
            lines.append(f"{name:<20} {c.minimum:>10.4g} {c.maximum:>10.4g} {c.levels:>7}  {unit}"
                         .rstrip())
        lines.append(f"violations: {self.errors} errors, {self.warnings} warnings")
        for g in self.groups():
            shown = ", ".join(str(i) for i in g.indices) + (", …" if g.count > len(g.indices) else "")
            lines.append(f"  {g.severity} ×{g.count} {g.parameter} ({g.rule}), trials {shown}: "
                         f"{g.example}")
        return "\n".join(lines)


def _changes(count: int) -> str:
    return f"{count} change{'' if count == 1 else 's'}"


def summarize(
    spec: ExperimentSpec,
    trials: Sequence[Trial],
    violations: Sequence[Violation],
    rig: RigSpec | None = None,
    rig_label: str | None = None,
) -> PlanSummary:
    """The dry-run summary of a plan (`rig` defaults to the one the spec names; `rig_label`
    names the rig given instead, e.g. `--rig`)."""
    rig = rig if rig is not None else load_rig_for(spec)
    coverage = {}
    if trials:
        for name, values in trial_columns(trials).items():
            levels = len(np.unique(np.round(values, 9)))
            coverage[name] = Coverage(float(values.min()), float(values.max()), levels)
    return PlanSummary(
        name=spec.name,
        finger=spec.finger,
        rig=spec.rig if rig_label is None else rig_label,
        mode=spec.sweep.mode,
        order=spec.sweep.order,
        trial_count=len(trials),
        coverage=coverage,
        lab_time=lab_time(trials, rig),
        violations=tuple(violations),
        approach=spec.approach,
        lab_time_by_approach={
            "as-specified": lab_time(as_specified(trials), rig),
            "fast": lab_time(with_fast_approach(trials, rig), rig),
        },
    )
