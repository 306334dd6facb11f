"""The safety envelope, checked on every planned trial before anything moves.

Per finger, each parameter must lie in the range that proved safe on the real rig (widened only
by the rig file). Cross-parameter checks add what a single range cannot say: where the arm stops
relative to the keybed, whether the commanded speed is reached before the finger meets the key,
and whether the whole stroke stays inside the UR5's workspace box.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from pianobot.errors import InputError
from pianobot.plan.trial import FloatArray, Trial, trial_columns
from pianobot.spec import (
    KEY_DIP_M,
    PARAMETER_NAMES,
    PARAMETERS,
    Finger,
    Limits,
    RigSpec,
)
from pianobot.spec.parameters import format_value

Severity = Literal["error", "warning"]
# A commanded speed counts as reached when the arm gets within this fraction of it at contact.
REACH_TOLERANCE = 1e-3


@dataclass(frozen=True)
class Violation:
    """One trial outside the envelope (error: refused) or likely not as intended (warning)."""

    index: int  # the trial's position in the run order
    trial_id: str
    parameter: str
    value: float
    allowed: tuple[float, float]  # [low, high] in the parameter's unit
    message: str
    severity: Severity
    rule: str  # envelope | bounds | keybed | reach | workspace

    def to_dict(self) -> dict[str, object]:
        """Plain JSON-able dict."""
        return {
            "index": self.index,
            "trial_id": self.trial_id,
            "parameter": self.parameter,
            "value": self.value,
            "allowed": list(self.allowed),
            "message": self.message,
            "severity": self.severity,
            "rule": self.rule,
        }


def check_envelope(
    trials: Sequence[Trial],
    finger: Finger,
    rig: RigSpec | None = None,
    *,
    rig_label: str = "the rig file",
) -> list[Violation]:
    """Every envelope violation of `trials` for `finger` on `rig`, ordered by trial index."""
    rig = rig if rig is not None else RigSpec()
    envelope = rig.envelope_for(finger, rig_label)
    columns = trial_columns(trials)
    found: list[Violation] = []
    for name in PARAMETER_NAMES:
        found += _bounds(trials, name, columns[name])
        if name in envelope:
            found += _outside(trials, finger, name, columns[name], envelope[name])
    found += _reach(trials, columns)
    found += _workspace(trials, rig)
    return sorted(found, key=lambda v: (v.index, v.severity != "error", v.parameter))


def raise_for_errors(violations: Sequence[Violation], label: str) -> None:
    """Raise an InputError for the first error-severity violation (warnings pass)."""
    errors = [v for v in violations if v.severity == "error"]
    if not errors:
        return
    first = errors[0]
    more = f" ({len(errors) - 1} more trial violation(s))" if len(errors) > 1 else ""
    raise InputError(first.message + more, f"{label}: trial {first.index} ({first.parameter})")


def contact_speeds_mps(
    distance_m: FloatArray, depth_m: FloatArray, velocity_mps: FloatArray, accel_mps2: FloatArray
) -> FloatArray:
    """Arm speed where the fingertip meets the resting key, for many trapezoid down moves.

    The vectorised form of `physics.trajectory.contact_speed_mps`: the move of distance + depth
    peaks at min(v, √(a·(distance + depth))) (a triangle when too short to cruise); after the
    run-up it has at most √(2·a·distance), and braking for the end caps it at √(2·a·depth).
    """
    with np.errstate(invalid="ignore"):
        peak = np.minimum(velocity_mps, np.sqrt(accel_mps2 * (distance_m + depth_m)))
        run_up = np.sqrt(2 * accel_mps2 * distance_m)
        braking = np.sqrt(2 * accel_mps2 * depth_m)
        speed: FloatArray = np.minimum(peak, np.minimum(run_up, braking))
    return speed


def _bounds(trials: Sequence[Trial], name: str, values: FloatArray) -> list[Violation]:
    p = PARAMETERS[name]
    return [
        Violation(i, trials[i].trial_id, name, float(values[i]), (p.minimum, p.maximum),
                  f"{name} {format_value(float(values[i]))} is not a valid value {p.bounds_text()}",
                  "error", "bounds")
        for i in np.flatnonzero(~p.bounds_mask(values)).tolist()
    ]


def _outside(
    trials: Sequence[Trial], finger: Finger, name: str, values: FloatArray, limits: Limits
) -> list[Violation]:
    unit = PARAMETERS[name].unit
    source = f" ({limits.source})" if limits.source else ""
    out = []
    for i in np.flatnonzero(~limits.mask(values)):
        value = float(values[i])
        rule = "envelope"
        message = (f"{name} {format_value(value)} {unit} is outside {limits.text(unit)} "
                   f"for the {finger} finger{source}")
        if name == "depth_m" and value > limits.high:
            # Past the key dip the key sits on the keybed and the finger must absorb the rest.
            rule = "keybed"
            message = (f"depth {format_value(value)} m drives the arm "
                       f"{(value - KEY_DIP_M) * 1e3:.1f} mm past the keybed (key dip "
                       f"{KEY_DIP_M * 1e3:.0f} mm); the {finger} finger is cleared for "
                       f"{(limits.high - KEY_DIP_M) * 1e3:.1f} mm{source}")
        elif limits.low == limits.high:
            message = (f"{name} must be {format_value(limits.low)} {unit} for the {finger} "
                       f"finger{source}, got {format_value(value)}")
        out.append(Violation(int(i), trials[int(i)].trial_id, name, value,
                             (limits.low, limits.high), message, "error", rule))
    return out


def _reach(trials: Sequence[Trial], columns: dict[str, FloatArray]) -> list[Violation]:
    """Warn where the arm meets the key slower than commanded (the study did this often).

    A trial that starts in contact (distance 0) has no impact speed to reach and is skipped.
    """
    distance, depth = columns["distance_m"], columns["depth_m"]
    v, a = columns["down_velocity_mps"], columns["acceleration_mps2"]
    reached = contact_speeds_mps(distance, depth, v, a)
    with np.errstate(invalid="ignore"):
        slow = (distance > 0) & (reached < v * (1 - REACH_TOLERANCE))
    out = []
    for i in np.flatnonzero(slow):
        t = trials[int(i)]
        if np.sqrt(2 * t.acceleration_mps2 * t.distance_m) < t.down_velocity_mps:
            why = f"still accelerating after the {format_value(t.distance_m)} m run-up"
        else:
            why = f"already braking {format_value(t.depth_m)} m before the end of the move"
        out.append(Violation(
            int(i), t.trial_id, "down_velocity_mps", t.down_velocity_mps, (0.0, float(reached[i])),
            f"the arm meets the key at {reached[i]:.3g} m/s, not the commanded "
            f"{format_value(t.down_velocity_mps)} m/s: at {format_value(t.acceleration_mps2)} "
            f"m/s² it is {why}", "warning", "reach"))
    return out


def _workspace(trials: Sequence[Trial], rig: RigSpec) -> list[Violation]:
    """On a calibrated UR5, the stroke's lowest and highest TCP heights must be in the box.

    The reference pose has the fingertip resting on a key, so the stroke spans from
    `depth` below it to `distance` (+ the safe lift) above it.
    """
    ur5 = rig.ur5
    if ur5 is None or ur5.reference_pose is None:
        return []
    z_rest = ur5.reference_pose[2]
    z_min, z_max = ur5.workspace_min_m[2], ur5.workspace_max_m[2]
    out = []
    for i, t in enumerate(trials):
        low = z_rest - t.depth_m
        high = z_rest + t.distance_m + ur5.safe_lift_m
        if low < z_min:
            out.append(Violation(i, t.trial_id, "depth_m", t.depth_m, (0.0, z_rest - z_min),
                                 f"the TCP would go down to z = {low:.4f} m, below the workspace "
                                 f"floor {z_min:.4f} m", "error", "workspace"))
        if high > z_max:
            out.append(Violation(i, t.trial_id, "distance_m", t.distance_m,
                                 (0.0, z_max - z_rest - ur5.safe_lift_m),
                                 f"the TCP would rise to z = {high:.4f} m (with the safe lift), "
                                 f"above the workspace ceiling {z_max:.4f} m", "error", "workspace"))
    return out
