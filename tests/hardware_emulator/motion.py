"""Tool motion of the emulated arm: UR's linear move as a trapezoid in path length, and stops.

A `movel(pose, a, v)` moves the TCP along the straight line to `pose` with the speed profile UR
documents: accelerate at `a`, cruise at `v`, decelerate at `a`; a move too short to reach `v`
is a triangle with peak sqrt(a·L). The profile runs on a *trajectory clock*: the speed slider
and the trajectory limiter scale time (speed by f, acceleration by f²), a pause freezes it.
A stop decelerates from the current tool speed at the given rate along the same line, on the
wall clock. Written from UR's description, not from pianobot's physics (the tests compare the
two).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

Pose = tuple[float, float, float, float, float, float]


class Trapezoid:
    """Path length s(τ) of a point-to-point move of length L (m) at speed v, acceleration a."""

    def __init__(self, length_m: float, speed_mps: float, acceleration_mps2: float) -> None:
        if speed_mps <= 0 or acceleration_mps2 <= 0:
            raise ValueError("speed and acceleration must be > 0")
        self.length_m = length_m
        self.acceleration = acceleration_mps2
        if length_m * acceleration_mps2 >= speed_mps * speed_mps:
            self.peak = speed_mps
            self.t_ramp = speed_mps / acceleration_mps2
            self.t_cruise = (length_m - speed_mps * self.t_ramp) / speed_mps
        else:  # never reaches v: a triangle
            self.peak = math.sqrt(acceleration_mps2 * length_m)
            self.t_ramp = self.peak / acceleration_mps2
            self.t_cruise = 0.0
        self.duration_s = 2 * self.t_ramp + self.t_cruise

    def at(self, tau_s: float) -> tuple[float, float]:
        """(s, ds/dτ) at trajectory time τ."""
        a, tr, vp = self.acceleration, self.t_ramp, self.peak
        if tau_s <= 0:
            return 0.0, 0.0
        if tau_s >= self.duration_s:
            return self.length_m, 0.0
        if tau_s < tr:
            return 0.5 * a * tau_s * tau_s, a * tau_s
        if tau_s <= tr + self.t_cruise:
            return 0.5 * vp * tr + vp * (tau_s - tr), vp
        left = self.duration_s - tau_s
        return self.length_m - 0.5 * a * left * left, a * left


class LinearMove:
    """A movel in progress: position along the line from `start` to `target`."""

    def __init__(self, start: Sequence[float], target: Sequence[float], speed_mps: float,
                 acceleration_mps2: float) -> None:
        self.start = tuple(float(v) for v in start)
        self.target = tuple(float(v) for v in target)
        self.length_m = math.dist(self.start[:3], self.target[:3])
        self.profile = Trapezoid(max(self.length_m, 1e-12), speed_mps, acceleration_mps2)
        self.tau_s = 0.0  # trajectory time
        self.done = self.length_m < 1e-9 and self._same_orientation()

    def _same_orientation(self) -> bool:
        return all(abs(a - b) < 1e-9 for a, b in zip(self.start[3:], self.target[3:], strict=True))

    def advance(self, dt_traj_s: float) -> None:
        self.tau_s += dt_traj_s
        if self.tau_s >= self.profile.duration_s:
            self.done = True

    def pose(self) -> Pose:
        s, _ = self.profile.at(self.tau_s)
        frac = 1.0 if self.done else s / self.profile.length_m
        return _lerp(self.start, self.target, frac)

    def path_speed(self) -> float:
        """ds/dτ (m per trajectory second)."""
        return 0.0 if self.done else self.profile.at(self.tau_s)[1]

    def direction(self) -> tuple[float, float, float]:
        if self.length_m < 1e-12:
            return (0.0, 0.0, 0.0)
        return tuple((t - s) / self.length_m for s, t in zip(self.start[:3], self.target[:3],
                                                            strict=True))  # type: ignore[return-value]


class Stop:
    """Decelerate from `speed_mps` along `direction` at `deceleration_mps2` (wall clock)."""

    def __init__(self, start: Sequence[float], direction: Sequence[float], speed_mps: float,
                 deceleration_mps2: float) -> None:
        self.start = tuple(float(v) for v in start)
        self.direction = tuple(float(v) for v in direction)
        self.speed = max(speed_mps, 0.0)
        self.decel = max(deceleration_mps2, 1e-6)
        self.t_s = 0.0
        self.duration_s = self.speed / self.decel
        self.done = self.duration_s <= 0

    def advance(self, dt_s: float) -> None:
        self.t_s = min(self.t_s + dt_s, self.duration_s)
        if self.t_s >= self.duration_s:
            self.done = True

    def pose(self) -> Pose:
        s = self.speed * self.t_s - 0.5 * self.decel * self.t_s * self.t_s
        p = list(self.start)
        for i in range(3):
            p[i] += self.direction[i] * s
        return tuple(p)  # type: ignore[return-value]

    def tool_speed(self) -> float:
        return max(self.speed - self.decel * self.t_s, 0.0)


def _lerp(a: Sequence[float], b: Sequence[float], frac: float) -> Pose:
    return tuple(x + frac * (y - x) for x, y in zip(a, b, strict=True))  # type: ignore[return-value]
