"""UR moveL motion profiles along the vertical axis.

A UR `moveL` runs a symmetric trapezoidal speed profile: accelerate at `a`, cruise at `v`,
decelerate at `a`. When the distance is too short to reach the cruise speed (d < v²/a) the
profile is a triangle with peak √(a·d) and duration 2√(d/a). A press is two such moves (down by
distance + depth, up by the same) with a hold between them.

The study's Simulink model drove the arm with a constant-speed ramp instead (no acceleration).
Here that is the limit a → ∞ of the same profile, selected with `profile="ramp"`; it is only
right at high acceleration, because deceleration caps the arm speed near the end of a move.

Coordinates: downward positive, metres; time zero is the start of the press's first motion.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
ProfileKind = Literal["trapezoid", "ramp"]
PROFILE_KINDS: tuple[ProfileKind, ...] = ("trapezoid", "ramp")


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


@dataclass(frozen=True)
class MoveProfile:
    """Exact phase times of one straight move (trapezoid, triangle or ramp).

    `acceleration_mps2` is `math.inf` for a constant-speed ramp; then `t_accel_s` is 0.
    """

    distance_m: float
    velocity_mps: float
    acceleration_mps2: float
    t_accel_s: float  # duration of the acceleration phase (= the deceleration phase)
    t_cruise_s: float  # duration at constant peak speed (0 for a triangle)
    duration_s: float
    peak_velocity_mps: float

    def sample(self, t_s: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Position travelled and speed at times `t_s` after the move starts (0 outside)."""
        t = np.asarray(t_s, dtype=np.float64)
        return _profile_state(
            t,
            np.float64(self.distance_m),
            np.float64(self.acceleration_mps2),
            np.float64(self.t_accel_s),
            np.float64(self.duration_s),
            np.float64(self.peak_velocity_mps),
        )

    def time_at_m(self, travelled_m: float) -> float:
        """Time after the start at which the move has covered `travelled_m` (0 ≤ s ≤ d)."""
        s = float(travelled_m)
        if not 0.0 <= s <= self.distance_m * (1 + 1e-12):
            raise ValueError(
                f"travelled distance should be in [0, {self.distance_m}] m, got {travelled_m}."
            )
        s = min(s, self.distance_m)
        a, ta, vp = self.acceleration_mps2, self.t_accel_s, self.peak_velocity_mps
        s_accel = 0.5 * vp * ta  # distance covered while accelerating (0 for a ramp)
        if s <= s_accel:
            return math.sqrt(2.0 * s / a)
        if s <= self.distance_m - s_accel:
            return ta + (s - s_accel) / vp
        return self.duration_s - math.sqrt(2.0 * (self.distance_m - s) / a)

    def speed_at_m(self, travelled_m: float) -> float:
        """Speed once the move has covered `travelled_m`.

        Accelerating from rest gives √(2·a·s); deceleration caps the speed at √(2·a·(d − s))
        with d − s the distance left, so a move cannot arrive fast at a point near its end.
        """
        s = min(max(float(travelled_m), 0.0), self.distance_m)
        if self.distance_m == 0.0:
            return 0.0
        a = self.acceleration_mps2
        return min(
            self.peak_velocity_mps, math.sqrt(2 * a * s), math.sqrt(2 * a * (self.distance_m - s))
        )


def move_profile(distance_m: float, velocity_mps: float, acceleration_mps2: float) -> MoveProfile:
    """The moveL profile for one move; `acceleration_mps2=math.inf` gives a constant-speed ramp.

    Raises ValueError for a negative distance or a non-positive speed or acceleration.
    """
    d, v, a = float(distance_m), float(velocity_mps), float(acceleration_mps2)
    if not (d >= 0.0 and math.isfinite(d)):
        raise ValueError(f"Move distance should be >= 0 m, got {distance_m}.")
    if not (v > 0.0 and math.isfinite(v)):
        raise ValueError(f"Move speed should be > 0 m/s, got {velocity_mps}.")
    if not a > 0.0:
        raise ValueError(f"Move acceleration should be > 0 m/s², got {acceleration_mps2}.")
    if d == 0.0:
        return MoveProfile(d, v, a, 0.0, 0.0, 0.0, 0.0)
    if d < v * v / a:
        # Too short to reach cruise speed: accelerate for half the distance, then brake.
        t_accel = math.sqrt(d / a)
        return MoveProfile(d, v, a, t_accel, 0.0, 2.0 * t_accel, a * t_accel)
    t_accel = v / a  # 0 for the ramp (a = inf)
    t_cruise = (d - v * t_accel) / v  # v·t_accel = v²/a: distance spent accelerating + braking
    return MoveProfile(d, v, a, t_accel, t_cruise, 2.0 * t_accel + t_cruise, v)


@dataclass(frozen=True)
class PressTiming:
    """Phase times of one press, measured from the start of the downward move."""

    down: MoveProfile
    up: MoveProfile
    t_down_end_s: float  # arm at its lowest point
    t_hold_end_s: float  # upward move starts
    t_end_s: float  # arm back at its start height

    @property
    def travel_m(self) -> float:
        """Total arm travel of each move: distance + depth."""
        return self.down.distance_m


def _acceleration(press: Press, profile: ProfileKind) -> float:
    if profile not in PROFILE_KINDS:
        raise ValueError(f"profile should be one of {PROFILE_KINDS}, got {profile!r}.")
    return math.inf if profile == "ramp" else press.acceleration_mps2


def press_timing(press: Press, profile: ProfileKind = "trapezoid") -> PressTiming:
    """Exact phase times of a press: down by distance + depth, hold, up by the same."""
    if press.depth_m < 0.0 or press.distance_m < 0.0:
        raise ValueError(
            f"Press distance and depth should be >= 0 m, got {press.distance_m} and {press.depth_m}."
        )
    if not press.hold_s >= 0.0:
        raise ValueError(f"Hold should be >= 0 s, got {press.hold_s}.")
    travel = press.distance_m + press.depth_m
    a = _acceleration(press, profile)
    down = move_profile(travel, press.down_velocity_mps, a)
    up = move_profile(travel, press.up_velocity_mps, a)
    t_down_end = down.duration_s
    t_hold_end = t_down_end + press.hold_s
    return PressTiming(down, up, t_down_end, t_hold_end, t_hold_end + up.duration_s)


def press_duration_s(press: Press, profile: ProfileKind = "trapezoid") -> float:
    """Time from the start of the downward move until the arm is back at its start height."""
    return press_timing(press, profile).t_end_s


def contact_speed_mps(press: Press, profile: ProfileKind = "trapezoid") -> float:
    """Arm speed when it has travelled `distance_m`, where the fingertip meets a rigid key.

    At low acceleration the arm may still be speeding up (√(2·a·s), s = distance) or already
    braking for the end of the move (√(2·a·depth)); a constant-speed ramp ignores both.
    """
    down = press_timing(press, profile).down
    return down.speed_at_m(press.distance_m)


def sample_presses(
    presses: Sequence[Press], t_s: npt.ArrayLike, *, profile: ProfileKind = "trapezoid"
) -> tuple[FloatArray, FloatArray]:
    """Arm position and speed of many presses on one time grid.

    Args:
        presses: the presses; each has its own time origin (start of its downward move).
        t_s: 1-D times relative to each press's motion start (may extend before 0 and past
            the end; the arm is at rest at 0 there).
        profile: "trapezoid" (UR moveL) or "ramp" (constant speed, the study's Simulink input).

    Returns:
        (x0_m, v0_mps), each of shape (len(presses), len(t_s)), downward positive.
    """
    t = np.asarray(t_s, dtype=np.float64)
    if t.ndim != 1:
        raise ValueError(f"t_s should be one-dimensional, got shape {t.shape}.")
    timings = [press_timing(p, profile) for p in presses]
    if not timings:
        empty = np.zeros((0, t.size))
        return empty, empty.copy()

    def column(values: list[float]) -> FloatArray:
        return np.asarray(values, dtype=np.float64)[:, None]

    travel = column([tm.down.distance_m for tm in timings])
    x_down, v_down = _profile_state(
        t[None, :],
        travel,
        column([tm.down.acceleration_mps2 for tm in timings]),
        column([tm.down.t_accel_s for tm in timings]),
        column([tm.down.duration_s for tm in timings]),
        column([tm.down.peak_velocity_mps for tm in timings]),
    )
    x_up, v_up = _profile_state(
        t[None, :] - column([tm.t_hold_end_s for tm in timings]),
        travel,
        column([tm.up.acceleration_mps2 for tm in timings]),
        column([tm.up.t_accel_s for tm in timings]),
        column([tm.up.duration_s for tm in timings]),
        column([tm.up.peak_velocity_mps for tm in timings]),
    )
    # The press is the down move minus the (later) up move of the same length: before the up
    # move starts it contributes 0, after it ends it cancels the down move exactly.
    return x_down - x_up, v_down - v_up


def _profile_state(
    tau: FloatArray,
    distance: FloatArray | np.float64,
    accel: FloatArray | np.float64,
    t_accel: FloatArray | np.float64,
    duration: FloatArray | np.float64,
    peak: FloatArray | np.float64,
) -> tuple[FloatArray, FloatArray]:
    """Travelled distance and speed of a move at times `tau` after its start (broadcasting)."""
    # A ramp has a = inf and t_accel = 0: its acceleration branches are never selected, but
    # np.where evaluates them, so give them a finite stand-in to avoid inf·0 = nan warnings.
    a = np.where(np.isfinite(accel), accel, 0.0)
    before = tau < 0.0
    after = tau >= duration
    rising = tau < t_accel
    braking = tau > duration - t_accel
    t_left = duration - tau
    s_accel = 0.5 * peak * t_accel
    x = np.where(
        rising,
        0.5 * a * tau**2,
        np.where(braking, distance - 0.5 * a * t_left**2, s_accel + peak * (tau - t_accel)),
    )
    v = np.where(rising, a * tau, np.where(braking, a * t_left, peak))
    x = np.where(before, 0.0, np.where(after, distance, x))
    v = np.where(before | after, 0.0, v)
    shape = np.broadcast_shapes(np.shape(tau), np.shape(distance))
    return (
        np.broadcast_to(x, shape).astype(np.float64),
        np.broadcast_to(v, shape).astype(np.float64),
    )
