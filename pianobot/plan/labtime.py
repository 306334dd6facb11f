"""How long a plan takes on the real rig: motion profiles plus the pauses between them.

Each press is its exact moveL timing (down, hold, up); between presses the rig pauses so key
and finger come to rest; every vacuum change (in run order, starting from atmospheric) waits
for the regulator and the particle jamming to settle; a change of key lifts the arm, moves
it sideways and lowers it again. The sim rig runs on a virtual clock, so this is lab time,
not the wall time of a simulated run.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from pianobot.physics.keyboard import REFERENCE_NOTE, key_center_m
from pianobot.physics.trajectory import move_profile, press_duration_s
from pianobot.spec import RigSpec

if TYPE_CHECKING:
    from pianobot.plan.trials import Trial

# Vacuum levels closer than this are the same setting (the regulator's tolerance is ~2 kPa).
SAME_VACUUM_KPA = 1e-6


@dataclass(frozen=True)
class LabTime:
    """A plan's lab-time estimate, by where the time goes (seconds)."""

    presses_s: float  # the moves and holds themselves
    pauses_s: float  # settle pauses between presses
    vacuum_s: float  # settling after vacuum changes
    travel_s: float  # moving between keys
    vacuum_changes: int
    key_changes: int

    @property
    def total_s(self) -> float:
        """Everything together."""
        return self.presses_s + self.pauses_s + self.vacuum_s + self.travel_s

    def to_dict(self) -> dict[str, float | int]:
        """Plain JSON-able dict (with the total)."""
        return {
            "total_s": self.total_s,
            "presses_s": self.presses_s,
            "pauses_s": self.pauses_s,
            "vacuum_s": self.vacuum_s,
            "travel_s": self.travel_s,
            "vacuum_changes": self.vacuum_changes,
            "key_changes": self.key_changes,
        }


def lab_time(trials: Sequence[Trial], rig: RigSpec | None = None) -> LabTime:
    """The lab-time estimate of running `trials` in their order on `rig`."""
    rig = rig if rig is not None else RigSpec()
    durations: dict[tuple[float, ...], float] = {}
    presses_s = 0.0
    vacuum_changes = key_changes = 0
    travel_s = 0.0
    vacuum_kpa = 0.0  # every run starts vented
    note: int | None = None
    for trial in trials:
        press = trial.press()
        key = (press.distance_m, press.depth_m, press.down_velocity_mps, press.up_velocity_mps,
               press.acceleration_mps2, press.hold_s)
        if key not in durations:
            durations[key] = press_duration_s(press)
        presses_s += durations[key]
        if abs(trial.vacuum_kpa - vacuum_kpa) > SAME_VACUUM_KPA:
            vacuum_changes += 1
            vacuum_kpa = trial.vacuum_kpa
        if note is not None and trial.note != note:
            key_changes += 1
            travel_s += key_change_s(note, trial.note, rig)
        note = trial.note
    return LabTime(
        presses_s=presses_s,
        pauses_s=len(trials) * rig.settle_s.between_presses_s,
        vacuum_s=vacuum_changes * rig.settle_s.after_vacuum_change_s,
        travel_s=travel_s,
        vacuum_changes=vacuum_changes,
        key_changes=key_changes,
    )


def estimate_lab_time_s(trials: Sequence[Trial], rig: RigSpec | None = None) -> float:
    """Total lab time of `trials` on `rig`, in seconds."""
    return lab_time(trials, rig).total_s


def key_change_s(from_note: int, to_note: int, rig: RigSpec) -> float:
    """Lift, move sideways to the other key, lower again: three moveLs at the travel settings."""
    keyboard = rig.keyboard
    reference = rig.ur5.reference_note if rig.ur5 is not None else REFERENCE_NOTE
    offsets = {int(n): dx for n, dx in keyboard.offsets_m.items()}

    def centre(note: int) -> float:
        return key_center_m(note, white_pitch_m=keyboard.white_key_pitch_m, offsets=offsets,
                            reference_note=reference)

    sideways_m = abs(centre(to_note) - centre(from_note))
    v, a = rig.travel.velocity_mps, rig.travel.acceleration_mps2
    vertical_s = move_profile(rig.lift_m, v, a).duration_s
    return 2 * vertical_s + move_profile(sideways_m, v, a).duration_s
