"""The UR arm's vertical moves: moveL trapezoids, press schedules, and the servo that tracks them.

A UR `moveL` over a distance D with speed limit v and acceleration a ramps up at a, cruises at v
and brakes at a. If D < v²/a it never reaches v: the profile is a triangle peaking at √(a·D)
after √(D/a). The finger therefore meets the key at whatever speed the profile has at that point,
which at low acceleration is below the commanded speed: braking over the last stretch s caps the
speed at √(2·a·s).

A press (the study's script) is one move down by distance + depth, a hold, and one move up by
the same. Moves are stored as rows of a float array so that the integrator can evaluate the
command without Python objects (columns `MOVE_COLUMNS`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

# t0, ramp time, cruise time, total time, peak speed, acceleration, direction (+1 down), start x
MOVE_COLUMNS = (
    "t0_s",
    "ramp_s",
    "cruise_s",
    "total_s",
    "peak_mps",
    "acc_mps2",
    "sign",
    "x_start_m",
)


@dataclass(frozen=True)
class Move:
    """One straight vertical move: signed distance (downward positive), speed limit, acceleration."""

    t0_s: float
    distance_m: float
    speed_mps: float
    acceleration_mps2: float

    def __post_init__(self) -> None:
        if not (self.speed_mps > 0 and self.acceleration_mps2 > 0):
            raise ValueError(
                f"a move needs speed > 0 and acceleration > 0, got {self.speed_mps}, "
                f"{self.acceleration_mps2}"
            )

    @property
    def timing(self) -> tuple[float, float, float, float]:
        """(ramp time, cruise time, total time, peak speed) of the profile."""
        d, v, a = abs(self.distance_m), self.speed_mps, self.acceleration_mps2
        if d * a < v * v:  # triangle: braking starts before the speed limit is reached
            ramp = math.sqrt(d / a)
            return ramp, 0.0, 2.0 * ramp, a * ramp
        ramp = v / a
        cruise = (d - v * v / a) / v
        return ramp, cruise, 2.0 * ramp + cruise, v

    @property
    def duration_s(self) -> float:
        return self.timing[2]

    @property
    def end_s(self) -> float:
        return self.t0_s + self.duration_s


def move_table(moves: list[Move]) -> FloatArray:
    """The moves as the integrator's table (columns `MOVE_COLUMNS`); moves must not overlap."""
    rows = []
    x = 0.0
    last_end = -math.inf
    for move in sorted(moves, key=lambda m: m.t0_s):
        if move.t0_s < last_end - 1e-12:
            raise ValueError(f"moves overlap: one starts at {move.t0_s} s before {last_end} s")
        ramp, cruise, total, peak = move.timing
        rows.append([move.t0_s, ramp, cruise, total, peak, move.acceleration_mps2,
                     math.copysign(1.0, move.distance_m), x])  # fmt: skip
        x += move.distance_m
        last_end = move.t0_s + total
    if not rows:
        return np.zeros((0, len(MOVE_COLUMNS)))
    return np.asarray(rows, dtype=np.float64)


def command(t_s: FloatArray, table: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Commanded position and speed at times `t_s` (vectorised twin of the integrator's one)."""
    t = np.asarray(t_s, dtype=np.float64)
    x = np.zeros_like(t)
    v = np.zeros_like(t)
    for t0, ramp, cruise, total, peak, acc, sign, x_start in table:
        tau = t - t0
        d = sign * (peak * (ramp + cruise))  # signed distance of the move
        after = tau >= total
        up = (tau >= 0) & (tau < ramp)
        flat = (tau >= ramp) & (tau < ramp + cruise)
        down = (tau >= ramp + cruise) & (tau < total)
        r = total - tau
        x = np.where(up, x_start + sign * 0.5 * acc * tau**2, x)
        x = np.where(flat, x_start + sign * (0.5 * acc * ramp**2 + peak * (tau - ramp)), x)
        x = np.where(down, x_start + d - sign * 0.5 * acc * r**2, x)
        x = np.where(after, x_start + d, x)
        v = np.where(up, sign * acc * tau, v)
        v = np.where(flat, sign * peak, v)
        v = np.where(down, sign * acc * r, v)
    return x, v


def breakpoints(table: FloatArray, shift_s: float = 0.0) -> FloatArray:
    """Times where the commanded acceleration jumps (the integrator lands a step on each)."""
    if table.size == 0:
        return np.zeros(0)
    t0, ramp, cruise, total = table[:, 0], table[:, 1], table[:, 2], table[:, 3]
    points = np.concatenate([t0, t0 + ramp, t0 + ramp + cruise, t0 + total]) + shift_s
    return np.unique(points)


@dataclass(frozen=True)
class PressCommand:
    """What the lab commanded for one keystroke (a lab knows this even when mocap does not)."""

    t_start_s: float  # motion start
    speed_mps: float  # down speed (up uses `up_speed_mps`)
    acceleration_mps2: float
    depth_m: float  # travel beyond touching the key
    distance_m: float  # hover above the key at the start
    hold_s: float
    up_speed_mps: float

    def moves(self) -> list[Move]:
        travel = self.distance_m + self.depth_m
        down = Move(self.t_start_s, travel, self.speed_mps, self.acceleration_mps2)
        up = Move(down.end_s + self.hold_s, -travel, self.up_speed_mps, self.acceleration_mps2)
        return [down, up]

    @property
    def t_end_s(self) -> float:
        """Motion end (the arm is back at its start pose)."""
        return self.moves()[1].end_s

    def to_dict(self) -> dict[str, float]:
        return {
            "t_start_s": self.t_start_s,
            "down_velocity_mps": self.speed_mps,
            "up_velocity_mps": self.up_speed_mps,
            "acceleration_mps2": self.acceleration_mps2,
            "depth_m": self.depth_m,
            "distance_m": self.distance_m,
            "hold_s": self.hold_s,
            "t_end_s": self.t_end_s,
        }


@dataclass(frozen=True)
class ArmServo:
    """How the real arm follows its command.

    kind: "exact" (follows the trapezoid), "lag" (first-order, time constant `tau_s`),
    "servo" (second-order, natural frequency `freq_hz`, damping ratio `zeta`), or "delay"
    (the trapezoid `tau_s` late).
    """

    kind: str = "exact"
    tau_s: float = 0.0
    freq_hz: float = 0.0
    zeta: float = 1.0

    def code(self) -> int:
        return {"exact": 0, "lag": 1, "servo": 2, "delay": 3}[self.kind]

    def to_dict(self) -> dict[str, float | str]:
        return {"kind": self.kind, "tau_s": self.tau_s, "freq_hz": self.freq_hz, "zeta": self.zeta}
