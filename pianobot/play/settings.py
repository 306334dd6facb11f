"""How `play` presses keys: the fixed stroke geometry, candidate vacuum levels, timing margins."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class PlaySettings(BaseModel):
    """Settings of a performance (validated once; unknown keys are refused).

    The stroke geometry is fixed for a song: loudness is chosen per note by the down velocity
    and per phrase by the vacuum (the regulator needs seconds, so it cannot change per note).
    A short run-up (`distance_m`) keeps the lead from motion start to note-on short.
    """

    model_config = ConfigDict(extra="forbid")

    finger: Literal["soft", "rigid"] = Field("soft", description="Selects the safety envelope.")
    distance_m: float = Field(0.002, ge=0.0, le=0.05, description="Fingertip hover height above the key.")
    depth_m: float = Field(0.025, ge=0.0, le=0.1, description="Press depth below first contact.")
    acceleration_mps2: float = Field(2.0, gt=0.0, le=10.0, description="moveL acceleration of both moves.")
    up_velocity_mps: float = Field(0.2, gt=0.0, le=3.0, description="Speed of the upward move.")
    vacuum_levels_kpa: tuple[float, ...] = Field(
        (-80.0, -60.0, -40.0), min_length=1, description="Vacuum levels a phrase may use."
    )
    min_down_velocity_mps: float = Field(
        0.01, gt=0.0, description="Slowest down velocity considered (slower strokes are near silent)."
    )
    speeds: int = Field(24, ge=4, le=200, description="Down velocities tabulated per vacuum level.")
    tabulate_hold_s: float = Field(0.4, gt=0.0, le=2.0, description="Second hold at which hold is tabulated.")
    recovery_s: float = Field(
        0.6, ge=0.0, le=10.0,
        description="After the arm is back up, time until the next press may start (the soft "
        "finger rings after the fast up-move; the sim arm waits for rest).",
    )
    max_late_s: float = Field(
        0.025, ge=0.0, le=0.05,
        description="A note that cannot start on time is played late by up to this; later, it "
        "is skipped and reported so the notes after it stay in time.",
    )
    lead_in_s: float = Field(0.5, ge=0.0, description="Idle time on the rig clock before the first motion.")
    melody_rule: Literal["highest", "lowest"] = Field("highest", description="Which note of a chord is kept.")
    silent_p: float = Field(0.5, gt=0.0, lt=1.0, description="A stroke with p_silent at or above this is silent.")
