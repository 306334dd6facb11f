"""How `play` presses keys: candidate stroke geometries, vacuum levels, timing margins, warm-up.

The finger decides the defaults: a soft finger presses deep (its pad compresses ~15–20 mm
before the key moves) at a vacuum level per phrase and keeps 2 mm above the key when the arm
stops; a rigid finger presses just past what sounds the key, may wait 1 mm above it and has no
vacuum line. Every `None` below means the finger's default.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from pianobot.spec.parameters import Finger

# Press depth below first contact: the soft pad needs most of its proven 20–35 mm to push the
# key to the bottom; a rigid finger sounds the key well before its proven 8–15 mm, and every
# millimetre below the note-on is time the arm spends going down and up again after it.
DEFAULT_DEPTH_M: dict[str, float] = {"soft": 0.025, "rigid": 0.008}
# Hover heights (where the arm waits above the key) and the lowest height a stopped arm may
# leave the fingertip at (where a fast approach ends). A finger is a spring on the arm: when the
# arm stops at the travel moves' 4 m/s² the fingertip sways by m·a/k — about 1.6 mm for the soft
# pad at -80 kPa (70 g, ~170 N/m), 0.1 mm for a rigid finger — so the soft finger keeps 2 mm.
DEFAULT_DISTANCES_M: dict[str, tuple[float, ...]] = {"soft": (0.002, 0.005, 0.01), "rigid": (0.001, 0.002, 0.005, 0.01)}
DEFAULT_CLEARANCE_M: dict[str, float] = {"soft": 0.002, "rigid": 0.001}
# Vacuum levels a phrase may use; a rigid finger has no vacuum line (0 kPa, its envelope).
DEFAULT_VACUUM_LEVELS_KPA: dict[str, tuple[float, ...]] = {"soft": (-80.0, -60.0, -40.0), "rigid": (0.0,)}


class PlaySettings(BaseModel):
    """Settings of a performance (validated once; unknown keys are refused).

    Per song the planner picks one stroke geometry (hover distance × acceleration, at the play
    depth and the up velocity below): the one that allows the fastest tempo, then with the
    widest loudness range. Loudness is chosen per note by the down velocity and per phrase by the
    vacuum (the regulator needs seconds, so it cannot change per note). `None` for the
    acceleration or the up velocity means the finger's envelope maximum on the rig; `None` for
    the depth or the vacuum levels means the finger's default above.
    """

    model_config = ConfigDict(extra="forbid")

    finger: Finger = Field("soft", description="Selects the safety envelope and the defaults.")
    distances_m: tuple[float, ...] | None = Field(
        None, min_length=1,
        description="Hover heights above the key the planner may choose from (each in [0, 0.05]; "
        "null: the finger's default).",
    )
    clearance_m: float | None = Field(
        None, ge=0.0, le=0.05,
        description="Lowest height above the key where a fast approach may stop (null: the "
        "finger's default; never below the rig's approach clearance).",
    )
    depth_m: float | None = Field(None, ge=0.0, le=0.1, description="Press depth below first contact.")
    accelerations_mps2: tuple[float, ...] | None = Field(
        None, description="moveL accelerations the planner may choose from (null: the envelope's maximum).",
    )
    up_velocity_mps: float | None = Field(
        None, gt=0.0, le=3.0, description="Speed of the upward move (null: the envelope's maximum).",
    )
    vacuum_levels_kpa: tuple[float, ...] | None = Field(
        None, min_length=1, description="Vacuum levels a phrase may use (null: the finger's default)."
    )
    min_down_velocity_mps: float = Field(
        0.01, gt=0.0, description="Slowest down velocity considered (slower strokes are near silent)."
    )
    speeds: int = Field(48, ge=4, le=400, description="Down velocities tabulated per vacuum level.")
    tabulate_hold_s: float = Field(0.4, gt=0.0, le=2.0, description="Second hold at which hold is tabulated.")
    fast_approach: bool = Field(
        True, description="Approach at the rig's fast-move speed to just above the key, then press "
        "at the contact speed (a two-segment press), where that reaches the key sooner.",
    )
    loudness_tolerance: float = Field(
        1.0, ge=0.0, le=20.0,
        description="A note may sound this many MIDI velocity steps louder than its target when "
        "that lets it start in time (a faster stroke sounds sooner); the feasible tempo counts on "
        "it. One step is the piano's own resolution.",
    )
    recovery_s: float = Field(
        0.02, ge=0.0, le=10.0,
        description="After the arm is back up, time until it may move or press again (controller "
        "latency; the key's own return is planned from the predicted note-off instead).",
    )
    restrike_margin_s: float = Field(
        0.03, ge=0.0, le=1.0,
        description="A re-strike of the same key starts this long after the predicted note-off "
        "(the key must be back above its re-trigger depth).",
    )
    max_late_s: float = Field(
        0.025, ge=0.0, le=0.05,
        description="At a tempo the user asked for, a note that cannot start on time is played "
        "late by up to this; later, it is played louder than the tolerance allows, and only then "
        "skipped and reported, so the notes after it stay in time.",
    )
    lead_in_s: float = Field(0.5, ge=0.0, description="Idle time on the rig clock before the first motion.")
    melody_rule: Literal["highest", "lowest"] = Field("highest", description="Which note of a chord is kept.")
    silent_p: float = Field(0.5, gt=0.0, lt=1.0, description="A stroke with p_silent at or above this is silent.")
    warmup_strokes: int = Field(
        12, ge=0, le=200,
        description="Keystrokes of the warm-up per vacuum level the song uses (0: no warm-up).",
    )
    warmup_hold_s: float = Field(
        0.3, ge=0.0, le=2.0, description="Arm hold of every other warm-up stroke (teaches the hold slope)."
    )

    @property
    def play_depth_m(self) -> float:
        """The press depth (the finger's default when unset)."""
        return self.depth_m if self.depth_m is not None else DEFAULT_DEPTH_M[self.finger]

    @property
    def hovers_m(self) -> tuple[float, ...]:
        """The hover heights the planner may choose from (the finger's default when unset)."""
        return self.distances_m if self.distances_m is not None else DEFAULT_DISTANCES_M[self.finger]

    @property
    def approach_clearance_m(self) -> float:
        """The lowest stop of a fast approach above the key (the finger's default when unset)."""
        return self.clearance_m if self.clearance_m is not None else DEFAULT_CLEARANCE_M[self.finger]

    @property
    def levels_kpa(self) -> tuple[float, ...]:
        """The vacuum levels a phrase may use (the finger's default when unset)."""
        return self.vacuum_levels_kpa if self.vacuum_levels_kpa is not None else DEFAULT_VACUUM_LEVELS_KPA[self.finger]
