"""UR moveL motion profiles along the vertical axis.

A UR `moveL` runs a symmetric trapezoidal speed profile: accelerate at `a`, cruise at `v`,
decelerate at `a`. When the distance is too short to reach the cruise speed (d < v²/a) the
profile is a triangle with peak √(a·d) and duration 2√(d/a). A press is two such moves (down by
distance + depth, up by the same) with a hold between them.

A two-segment press (`Press.approach_m`, `Press.retract_m` > 0) adds up to two fast moves at the
travel speed: a first move down by `approach_m` that stops above the key, then the spec's move
for the rest of the way; and after lift-off, the spec's up move stops `retract_m` short of the top
and a fast move covers the rest. Four moves in all (fast down, down, up, fast up); with both
lengths 0 (the default) the fast moves are empty and the press is exactly the two-move one.
`physics.approach` plans the lengths so that the keystroke itself is unchanged.

The study's Simulink model drove the arm with a constant-speed ramp instead (no acceleration).
Here that is the limit a → ∞ of the same profile, selected with `profile="ramp"`; it is only
right at high acceleration, because deceleration caps the arm speed near the end of a move.

Coordinates: downward positive, metres; time zero is the start of the press's first motion.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
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

    A two-segment press covers the first `approach_m` of the way down and the last `retract_m`
    of the way up in separate moves at (travel velocity, travel acceleration); the spec's moves
    cover the rest. Both 0 (the default): the spec's two moves, nothing else.
    """

    distance_m: float
    depth_m: float
    down_velocity_mps: float
    up_velocity_mps: float
    acceleration_mps2: float
    hold_s: float = 0.0
    approach_m: float = 0.0  # fast first move down (must stop above the key: < distance_m)
    retract_m: float = 0.0  # fast last move up, after lift-off (<= distance_m)
    travel_velocity_mps: float = 0.25  # speed of the fast moves (UR moveL default)
    travel_acceleration_mps2: float = 1.0  # acceleration of the fast moves

    @property
    def two_segment(self) -> bool:
        """Whether the press has a fast approach or a fast retract."""
        return self.approach_m > 0.0 or self.retract_m > 0.0

    def as_specified(self) -> Press:
        """The same press with the spec's two moves only (no fast approach or retract)."""
        return Press(distance_m=self.distance_m, depth_m=self.depth_m, down_velocity_mps=self.down_velocity_mps,
                     up_velocity_mps=self.up_velocity_mps, acceleration_mps2=self.acceleration_mps2,
                     hold_s=self.hold_s)


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


NO_MOVE = MoveProfile(0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class PressTiming:
    """Phase times of one press, measured from the start of its first move.

    `down` and `up` are the moves at the spec's speeds (the whole travel for a plain press);
    `approach` and `retract` are the fast moves of a two-segment press (`NO_MOVE` otherwise).
    """

    down: MoveProfile
    up: MoveProfile
    t_down_end_s: float  # arm at its lowest point
    t_hold_end_s: float  # upward move starts
    t_end_s: float  # arm back at its start height
    approach: MoveProfile = field(default=NO_MOVE)
    retract: MoveProfile = field(default=NO_MOVE)

    @property
    def travel_m(self) -> float:
        """Total arm travel down (and up): distance + depth."""
        return self.approach.distance_m + self.down.distance_m

    @property
    def t_down_start_s(self) -> float:
        """The spec-speed down move starts (0 without a fast approach)."""
        return self.approach.duration_s

    @property
    def t_lifted_s(self) -> float:
        """The spec-speed up move ends and the fast retract starts (`t_end_s` without one)."""
        return self.t_hold_end_s + self.up.duration_s


def _acceleration(press: Press, profile: ProfileKind) -> float:
    if profile not in PROFILE_KINDS:
        raise ValueError(f"profile should be one of {PROFILE_KINDS}, got {profile!r}.")
    return math.inf if profile == "ramp" else press.acceleration_mps2


def check_press(press: Press) -> None:
    """Raise ValueError unless the press can be executed as commanded.

    Distance, depth and hold must be >= 0; a fast approach must stop before the fingertip
    reaches the key (approach_m < distance_m) and a fast retract must start no lower than the
    key surface (retract_m <= distance_m), both at a positive travel speed and acceleration.
    """
    if not (press.depth_m >= 0.0 and press.distance_m >= 0.0):
        raise ValueError(
            f"Press distance and depth should be >= 0 m, got {press.distance_m} and {press.depth_m}."
        )
    if not press.hold_s >= 0.0:
        raise ValueError(f"Hold should be >= 0 s, got {press.hold_s}.")
    if not (press.approach_m >= 0.0 and press.retract_m >= 0.0):
        raise ValueError(
            f"Fast move lengths should be >= 0 m, got approach_m {press.approach_m} and "
            f"retract_m {press.retract_m}."
        )
    if not press.two_segment:
        return
    if press.approach_m != 0.0 and not 0.0 < press.approach_m < press.distance_m:
        raise ValueError(
            f"A fast approach should stop above the key: approach_m in [0, {press.distance_m}) m, "
            f"got {press.approach_m}."
        )
    if not 0.0 <= press.retract_m <= press.distance_m:
        raise ValueError(
            f"A fast retract should start at or above the key surface: retract_m in "
            f"[0, {press.distance_m}] m, got {press.retract_m}."
        )
    for name in ("travel_velocity_mps", "travel_acceleration_mps2"):
        value = getattr(press, name)
        if not (value > 0.0 and math.isfinite(value)):
            raise ValueError(f"{name} should be > 0 for a two-segment press, got {value}.")


@lru_cache(maxsize=4096)
def press_timing(press: Press, profile: ProfileKind = "trapezoid") -> PressTiming:
    """Exact phase times of a press: (fast approach,) down, hold, up (, fast retract).

    Cached: a sweep asks for the same press's timing several times per keystroke (the result
    is immutable).
    """
    check_press(press)
    travel = press.distance_m + press.depth_m
    a = _acceleration(press, profile)
    down = move_profile(travel - press.approach_m, press.down_velocity_mps, a)
    up = move_profile(travel - press.retract_m, press.up_velocity_mps, a)
    if not press.two_segment:
        t_hold_end = down.duration_s + press.hold_s
        return PressTiming(down, up, down.duration_s, t_hold_end, t_hold_end + up.duration_s)
    a_fast = math.inf if profile == "ramp" else press.travel_acceleration_mps2
    approach = move_profile(press.approach_m, press.travel_velocity_mps, a_fast)
    retract = move_profile(press.retract_m, press.travel_velocity_mps, a_fast)
    t_down_end = approach.duration_s + down.duration_s
    t_hold_end = t_down_end + press.hold_s
    t_end = t_hold_end + up.duration_s + retract.duration_s
    return PressTiming(down, up, t_down_end, t_hold_end, t_end, approach, retract)


def press_duration_s(press: Press, profile: ProfileKind = "trapezoid") -> float:
    """Time from the start of the downward move until the arm is back at its start height."""
    return press_timing(press, profile).t_end_s


def contact_speed_mps(press: Press, profile: ProfileKind = "trapezoid") -> float:
    """Arm speed when it has travelled `distance_m`, where the fingertip meets a rigid key.

    At low acceleration the arm may still be speeding up (√(2·a·s), s = distance) or already
    braking for the end of the move (√(2·a·depth)); a constant-speed ramp ignores both. With a
    fast approach, contact happens in the spec-speed move, `distance − approach_m` after its start.
    """
    down = press_timing(press, profile).down
    return down.speed_at_m(press.distance_m - press.approach_m)


def contact_time_s(press: Press, profile: ProfileKind = "trapezoid") -> float:
    """Time from the start of the press until the arm has travelled `distance_m` (rigid key)."""
    timing = press_timing(press, profile)
    return timing.t_down_start_s + timing.down.time_at_m(press.distance_m - press.approach_m)


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

    def move(moves: list[MoveProfile], start_s: list[float]) -> tuple[FloatArray, FloatArray]:
        return _profile_state(
            t[None, :] - column(start_s),
            column([m.distance_m for m in moves]),
            column([m.acceleration_mps2 for m in moves]),
            column([m.t_accel_s for m in moves]),
            column([m.duration_s for m in moves]),
            column([m.peak_velocity_mps for m in moves]),
        )

    x_down, v_down = move([tm.down for tm in timings], [tm.t_down_start_s for tm in timings])
    x_up, v_up = move([tm.up for tm in timings], [tm.t_hold_end_s for tm in timings])
    # The press is the down move minus the (later) up move: before the up move starts it
    # contributes 0, after it ends it cancels what the down move covered.
    x, v = x_down - x_up, v_down - v_up
    if any(p.two_segment for p in presses):
        # The fast moves add the rest: the approach before the down move, the retract after
        # the up move (empty moves of plain presses add exactly 0).
        x_in, v_in = move([tm.approach for tm in timings], [0.0] * len(timings))
        x_out, v_out = move([tm.retract for tm in timings], [tm.t_lifted_s for tm in timings])
        x, v = x + x_in - x_out, v + v_in - v_out
    return x, v


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
