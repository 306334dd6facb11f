"""UR moveL motion profiles along the vertical axis."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Press:
    """One keystroke as the arm executes it (downward positive, metres, seconds).

    The fingertip starts `distance_m` above the key surface; the arm moves down by
    distance + depth at (down velocity, acceleration), holds, and moves back up by the same.
    """

    distance_m: float
    depth_m: float
    down_velocity_mps: float
    up_velocity_mps: float
    acceleration_mps2: float
    hold_s: float = 0.0
