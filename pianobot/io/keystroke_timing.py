"""When each keystroke line of an old log could sound, predicted from its control values.

A line of a keystroke log is one robot cycle: (for sequence logs) a sideways move to the key,
the downward moveL by distance + depth, the hold, the upward moveL, then the MIDI read and the
print. Every move is a UR moveL trapezoid (accelerate at a, cruise at v, brake at a; a triangle
when the move is too short to reach v). From the logged values this module predicts, per line:

- `motion_s`: the motion time of the cycle (move + down + hold + up). What the log does not
  explain (the read, the print, sleeps, the approach) is a per-session constant that the
  assignment estimates from the timestamps (`keystroke_assign`).
- the *note-on window* `[on_early_s, on_late_s]` after the motion starts: the note cannot sound
  before the fingertip has touched the key and pushed it `KEY_TRIGGER_M` down, nor much after the
  arm has stopped at the bottom (the key is driven by the arm; a compliant finger lets it trail
  by a fraction of a second, `LATE_MARGIN_S`).

Values a layout does not log are handled conservatively: an unknown depth counts as 0 (the
constant absorbs it), an unknown acceleration as a constant-speed ramp; a line without a speed
has no prediction (`known` False) and the assignment trusts its timing less.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pianobot.physics.keyboard import HIGHEST_NOTE, LOWEST_NOTE, key_center_m
from pianobot.spec.parameters import recorded_or_followed

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

# The digital piano's note-on comes near the bottom of the ~10 mm key dip; half of it is the
# earliest the key can have triggered after the fingertip touched it.
KEY_TRIGGER_M = 0.005
LATE_MARGIN_S = 0.15  # a key pushed through a compliant finger trails the arm's stop a little


@dataclass(frozen=True)
class LineTiming:
    """Per-line predictions (seconds from the start of the line's motion)."""

    motion_s: FloatArray
    on_early_s: FloatArray
    on_late_s: FloatArray
    known: BoolArray  # False: no speed logged, `motion_s` is a placeholder (0)

    def __len__(self) -> int:
        return int(self.motion_s.size)

    def take(self, index: IntArray) -> LineTiming:
        """The predictions of a subset of lines."""
        return LineTiming(
            self.motion_s[index], self.on_early_s[index], self.on_late_s[index], self.known[index]
        )


def move_duration_s(
    distance_m: FloatArray, velocity_mps: FloatArray, accel_mps2: FloatArray
) -> FloatArray:
    """Duration of moveL trapezoids (triangles when d < v²/a); a = inf gives a constant-speed ramp."""
    d, v, a = np.broadcast_arrays(distance_m, velocity_mps, accel_mps2)
    with np.errstate(invalid="ignore", divide="ignore"):
        triangle = d < v * v / a
        out: FloatArray = np.where(triangle, 2.0 * np.sqrt(d / a), d / v + v / a)
    return out


def time_at_m(
    travelled_m: FloatArray,
    distance_m: FloatArray,
    velocity_mps: FloatArray,
    accel_mps2: FloatArray,
) -> FloatArray:
    """Time after a move's start at which it has covered `travelled_m` (clipped to [0, d])."""
    s, d, v, a = np.broadcast_arrays(travelled_m, distance_m, velocity_mps, accel_mps2)
    s = np.clip(s, 0.0, d)
    with np.errstate(invalid="ignore", divide="ignore"):
        peak = np.minimum(v, np.sqrt(a * d))
        t_accel = peak / a
        s_accel = 0.5 * peak * t_accel
        total = move_duration_s(d, v, a)
        accelerating = np.sqrt(2.0 * s / a)
        cruising = t_accel + (s - s_accel) / peak
        braking = total - np.sqrt(np.maximum(2.0 * (d - s) / a, 0.0))
        out = np.where(s <= s_accel, accelerating, np.where(s <= d - s_accel, cruising, braking))
    return np.where(d > 0, out, 0.0)


def line_timing(
    params: Mapping[str, FloatArray],
    notes: IntArray | None = None,
    up_travel: str = "distance+depth",
) -> LineTiming:
    """Predicted motion time and note-on window of each line.

    Args:
        params: arrays of pianobot parameter columns (`distance_m`, `depth_m`, `down_velocity_mps`,
            `up_velocity_mps`, `acceleration_mps2`, `up_acceleration_mps2`, `hold_s`, and for
            sequence logs `move_velocity_mps`, `move_acceleration_mps2`); missing ones are NaN.
        notes: the key of each line (MIDI, -1 unknown), for the sideways move between keys.
        up_travel: "distance+depth" (the arm returns to its start height, as in the sweeps) or
            "depth" (the sequence script rose by the press depth only).
    """
    n = len(next(iter(params.values()))) if params else 0

    def column(name: str) -> FloatArray:
        value = params.get(name)
        return np.full(n, np.nan) if value is None else np.asarray(value, dtype=np.float64)

    distance = np.nan_to_num(column("distance_m"), nan=0.0)
    depth = np.nan_to_num(column("depth_m"), nan=0.0)  # unknown: the session constant absorbs it
    hold = np.nan_to_num(column("hold_s"), nan=0.0)
    v_down = column("down_velocity_mps")
    v_up = recorded_or_followed("up_velocity_mps", {"up_velocity_mps": column("up_velocity_mps"),
                                                    "down_velocity_mps": v_down})
    a_down = _acceleration(column("acceleration_mps2"))
    a_up = _acceleration(
        np.where(
            np.isfinite(column("up_acceleration_mps2")),
            column("up_acceleration_mps2"),
            column("acceleration_mps2"),
        )
    )
    known = np.isfinite(v_down) & (v_down > 0) & np.isfinite(v_up) & (v_up > 0)
    v_down, v_up = np.where(known, v_down, 1.0), np.where(known, v_up, 1.0)
    travel_down = distance + depth
    travel_up = depth if up_travel == "depth" else travel_down
    down_s = move_duration_s(travel_down, v_down, a_down)
    up_s = move_duration_s(travel_up, v_up, a_up)
    move_s = _sideways_s(column("move_velocity_mps"), column("move_acceleration_mps2"), notes, n)
    trigger = distance + np.minimum(depth, KEY_TRIGGER_M)
    early = move_s + time_at_m(trigger, travel_down, v_down, a_down)
    late = move_s + down_s + LATE_MARGIN_S
    motion = move_s + down_s + hold + up_s
    zero = np.zeros(n)
    return LineTiming(
        np.where(known, motion, zero),
        np.where(known, early, zero),
        np.where(known, late, zero),
        known,
    )


def _acceleration(values: FloatArray) -> FloatArray:
    """Unknown or non-physical accelerations become a ramp (a = inf): the shortest possible move."""
    return np.where(np.isfinite(values) & (values > 0), values, np.inf)


_KEY_POSITION_M = np.array(
    [key_center_m(n) if LOWEST_NOTE <= n <= HIGHEST_NOTE else np.nan for n in range(128)]
)


def _sideways_s(
    velocity: FloatArray, acceleration: FloatArray, notes: IntArray | None, n: int
) -> FloatArray:
    """Time of the sideways move from the previous line's key to this line's (0 where unknown)."""
    if notes is None or not np.isfinite(velocity).any():
        return np.zeros(n)
    position = np.where(
        (notes >= 0) & (notes < 128), _KEY_POSITION_M[np.clip(notes, 0, 127)], np.nan
    )
    step = np.abs(np.diff(position, prepend=np.nan))
    ok = np.isfinite(step) & np.isfinite(velocity) & (velocity > 0)
    duration = move_duration_s(
        np.where(ok, step, 0.0), np.where(ok, velocity, 1.0), _acceleration(acceleration)
    )
    return np.where(ok, duration, 0.0)
