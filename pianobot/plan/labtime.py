"""How long a plan takes on the real rig: motion profiles plus the pauses between them.

Each press is its exact moveL timing (down, hold, up; with a fast approach and retract, four
moves); between presses the rig pauses so key and finger come to rest, counted from lift-off:
a fast retract happens while the key settles, so it shortens the pause by its own duration; every vacuum change (in run order, starting from atmospheric) waits
for the regulator and the particle jamming to settle; a change of key lifts the arm, moves
it sideways and lowers it again. The sim rig runs on a virtual clock, so this is lab time,
not the wall time of a simulated run.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pianobot.physics.keyboard import REFERENCE_NOTE, key_center_m
from pianobot.physics.trajectory import move_profile
from pianobot.plan.trial import MOTION_COLUMNS, FloatArray, Trial, trial_columns
from pianobot.spec import RigSpec

# Vacuum levels closer than this are the same setting (the regulator's tolerance is ~2 kPa):
# here, and for the station that decides when to wait for a new level (rig.station).
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
    c = trial_columns(trials)
    m = trial_columns(trials, MOTION_COLUMNS)
    travel_m = c["distance_m"] + c["depth_m"]
    v_fast, a_fast = m["travel_velocity_mps"], m["travel_acceleration_mps2"]
    retract_s = move_durations_s(m["retract_m"], v_fast, a_fast)
    presses_s = float(np.sum(
        move_durations_s(m["approach_m"], v_fast, a_fast)
        + move_durations_s(travel_m - m["approach_m"], c["down_velocity_mps"], c["acceleration_mps2"])
        + c["hold_s"]
        + move_durations_s(travel_m - m["retract_m"], c["up_velocity_mps"], c["acceleration_mps2"])
        + retract_s
    ))
    # The pause lets the key and finger come to rest after lift-off; a fast retract is part of it.
    pauses_s = float(np.sum(np.maximum(rig.settle_s.between_presses_s - retract_s, 0.0)))
    # Every run starts vented; each change of level in run order waits for the regulator.
    previous_kpa = np.concatenate([[0.0], c["vacuum_kpa"][:-1]])
    vacuum_changes = int(np.count_nonzero(np.abs(c["vacuum_kpa"] - previous_kpa) > SAME_VACUUM_KPA))
    notes = [t.note for t in trials]
    moves = Counter((a, b) for a, b in zip(notes, notes[1:], strict=False) if a != b)
    travel_s = sum(count * key_change_s(a, b, rig) for (a, b), count in moves.items())
    return LabTime(
        presses_s=presses_s,
        pauses_s=pauses_s,
        vacuum_s=vacuum_changes * rig.settle_s.after_vacuum_change_s,
        travel_s=travel_s,
        vacuum_changes=vacuum_changes,
        key_changes=sum(moves.values()),
    )


def move_durations_s(
    distance_m: FloatArray, velocity_mps: FloatArray, accel_mps2: FloatArray
) -> FloatArray:
    """Durations of many moveL moves: the vectorised `physics.trajectory.move_profile`.

    A trapezoid spends v/a accelerating and v/a braking, covering v²/a, and cruises the rest:
    d/v + v/a in all. A move shorter than v²/a never reaches v: a triangle of 2·√(d/a). An
    empty move (d = 0) takes no time.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        triangle = distance_m < velocity_mps**2 / accel_mps2
        duration: FloatArray = np.where(
            triangle,
            2 * np.sqrt(distance_m / accel_mps2),
            distance_m / velocity_mps + velocity_mps / accel_mps2,
        )
    return np.where(distance_m > 0.0, duration, 0.0)


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
