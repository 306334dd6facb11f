"""How `play` presses keys: candidate stroke geometries, vacuum levels, timing margins."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class PlaySettings(BaseModel):
    """Settings of a performance (validated once; unknown keys are refused).

    Per song the planner picks one stroke geometry (hover distance × acceleration, at the play
    depth and the up velocity below): the one that plays the most notes on time, then with the
    widest loudness range; a fast tempo therefore gets a short hover and a brisk acceleration.
    Loudness is chosen per note by the down velocity and per phrase by the vacuum (the
    regulator needs seconds, so it cannot change per note). `None` for the acceleration or the
    up velocity means the finger's envelope maximum on the rig.
    """

    model_config = ConfigDict(extra="forbid")

    finger: Literal["soft", "rigid"] = Field("soft", description="Selects the safety envelope.")
    distances_m: tuple[float, ...] = Field(
        (0.002, 0.005, 0.01), min_length=1,
        description="Hover heights above the key the planner may choose from (each in [0, 0.05]).",
    )
    depth_m: float = Field(0.025, ge=0.0, le=0.1, description="Press depth below first contact.")
    accelerations_mps2: tuple[float, ...] | None = Field(
        None, description="moveL accelerations the planner may choose from (null: the envelope's maximum).",
    )
    up_velocity_mps: float | None = Field(
        None, gt=0.0, le=3.0, description="Speed of the upward move (null: the envelope's maximum).",
    )
    vacuum_levels_kpa: tuple[float, ...] = Field(
        (-80.0, -60.0, -40.0), min_length=1, description="Vacuum levels a phrase may use."
    )
    min_down_velocity_mps: float = Field(
        0.01, gt=0.0, description="Slowest down velocity considered (slower strokes are near silent)."
    )
    speeds: int = Field(24, ge=4, le=200, description="Down velocities tabulated per vacuum level.")
    tabulate_hold_s: float = Field(0.4, gt=0.0, le=2.0, description="Second hold at which hold is tabulated.")
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
        description="A note that cannot start on time is played late by up to this; later, it "
        "is played louder (a faster stroke has a shorter lead) and only then skipped and "
        "reported, so the notes after it stay in time.",
    )
    lead_in_s: float = Field(0.5, ge=0.0, description="Idle time on the rig clock before the first motion.")
    melody_rule: Literal["highest", "lowest"] = Field("highest", description="Which note of a chord is kept.")
    silent_p: float = Field(0.5, gt=0.0, lt=1.0, description="A stroke with p_silent at or above this is silent.")
