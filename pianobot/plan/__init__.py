"""Plans: the exact trials a spec runs, their safety check, lab time and dry-run summary.

    trials = expand(spec)                                  # pure, deterministic, stable ids
    violations = check_envelope(trials, spec.finger, rig)  # errors refuse, warnings inform
    print(summarize(spec, trials, violations, rig).to_text())
"""

from __future__ import annotations

from pianobot.durations import format_duration
from pianobot.plan.envelope import Violation, check_envelope, contact_speeds_mps, raise_for_errors
from pianobot.plan.expand import expand
from pianobot.plan.labtime import (
    LabTime,
    estimate_lab_time_s,
    key_change_s,
    lab_time,
    move_durations_s,
)
from pianobot.plan.size import DEFAULT_MAX_TRIALS, check_size, count_trials, estimated_lab_time_s
from pianobot.plan.summary import Coverage, PlanSummary, ViolationGroup, summarize
from pianobot.plan.trial import PLAN_COLUMNS, Trial, plan_frame, trial_columns
from pianobot.spec import resolved_spec_dict, spec_sha256

__all__ = [
    "DEFAULT_MAX_TRIALS",
    "PLAN_COLUMNS",
    "Coverage",
    "LabTime",
    "PlanSummary",
    "Trial",
    "Violation",
    "ViolationGroup",
    "check_envelope",
    "check_size",
    "contact_speeds_mps",
    "count_trials",
    "estimate_lab_time_s",
    "estimated_lab_time_s",
    "expand",
    "format_duration",
    "key_change_s",
    "lab_time",
    "move_durations_s",
    "plan_frame",
    "raise_for_errors",
    "resolved_spec_dict",
    "spec_sha256",
    "summarize",
    "trial_columns",
]
