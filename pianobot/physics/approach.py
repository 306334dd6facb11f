"""The fast approach: plan a two-segment press that leaves the keystroke itself unchanged.

A spec's press moves the arm down by distance + depth in one moveL at the contact speed, so a
5 cm run-up at 0.01 m/s takes 5 s of lab time before the finger even touches the key. The fast
approach covers most of that run-up at travel speed, stops, and lets a second moveL at the
spec's (v, a) do the rest. The second move starts from rest, so it can only reproduce the tail
of the spec's move, and only from the point where its own acceleration limit stops binding:

    a move from rest at s0 to the same end point, at the same (v, a), has the spec's speed
    min(v, √(2a·s), √(2a·(D − s))) at every s ≥ s0 + min(v²/(2a), (D − s0)/2)

(its speed is min(v, √(2a·(s − s0)), √(2a·(D − s))), and the middle term stops binding once the
move has reached the cruise speed, or, for a triangle, its peak). So the arm arrives at the key
in exactly the spec's kinematic state — speed and acceleration phase, cruising or already
braking — iff the second move starts at least min(v²/(2a), depth) above contact; a press still
accelerating when it touches the key (distance < v²/(2a)) has no exact shortcut at all.

The finger is a lightly damped spring on the arm (the published soft finger rings down with
time constant 2·m1/c0 ≈ 0.28 s), so an arm in the right state is not enough: the fingertip also
remembers how the arm moved just before. The plan therefore keeps the arm's motion identical
to the spec's for `settle_s` before contact: with s* the point the spec's move passes `settle_s`
before contact, the second move starts at s0 = s* − v²/(2a) when s* lies before the braking
phase (the move then cruises from s*), else at s0 = 2·s* − D (a triangle peaking at s*).
Any ringing from the fast move or the stop has decayed by exp(−settle_s/τ) at contact.

The retract is the mirror image with no memory to respect: after lift-off nothing the arm does
reaches the key. The spec's up move runs until the fingertip is `clearance_m` above the key's
rest surface, and only then may it brake; a fast move covers the rest of the way up.

A fast move shorter than `MIN_FAST_MOVE_M`, or one that saves less than `MIN_SAVING_S`, is
left out.
Everything works on columns, so a plan of a million trials is planned in one pass.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from pianobot.physics.trajectory import Press

FloatArray = npt.NDArray[np.float64]

MIN_FAST_MOVE_M = 1e-3  # a fast move shorter than this is not worth a second moveL
# Nor is one that saves less than this: the real arm pauses between two moveLs for a controller
# round trip (tens of ms), and a stop is one more chance for the finger to sway.
MIN_SAVING_S = 0.1


@dataclass(frozen=True)
class ApproachSettings:
    """How a two-segment press is planned (the rig file's `approach:` section)."""

    velocity_mps: float = 0.25  # travel speed of the fast moves
    acceleration_mps2: float = 1.0  # travel acceleration of the fast moves
    clearance_m: float = 0.005  # fingertip height above the key where a fast move must end
    settle_s: float = 1.5  # the arm moves exactly as specified for this long before contact


@dataclass(frozen=True)
class FastMoves:
    """Per trial: the lengths of the fast approach and retract (0 where there is none)."""

    approach_m: FloatArray
    retract_m: FloatArray


def plan_fast_moves(
    distance_m: npt.ArrayLike,
    depth_m: npt.ArrayLike,
    down_velocity_mps: npt.ArrayLike,
    up_velocity_mps: npt.ArrayLike,
    acceleration_mps2: npt.ArrayLike,
    settings: ApproachSettings,
) -> FastMoves:
    """The longest exact fast approach and retract of many presses (columns of equal length)."""
    d, depth, v, v_up, a = np.broadcast_arrays(*(
        np.atleast_1d(np.asarray(x, dtype=np.float64))
        for x in (distance_m, depth_m, down_velocity_mps, up_velocity_mps, acceleration_mps2)
    ))
    travel = d + depth
    with np.errstate(divide="ignore", invalid="ignore"):
        approach = _approach_m(d, travel, v, a, settings)
        retract = _retract_m(depth, travel, v_up, a, settings)
        # Keep a fast move only where it is long enough and makes the press shorter.
        saved_in = _moves_s(travel, v, a) - _fast_s(approach, settings) - _moves_s(travel - approach, v, a)
        approach = np.where((approach >= MIN_FAST_MOVE_M) & (saved_in >= MIN_SAVING_S), approach, 0.0)
        saved_out = (_moves_s(travel, v_up, a) - _fast_s(retract, settings)
                     - _moves_s(travel - retract, v_up, a))
        retract = np.where((retract >= MIN_FAST_MOVE_M) & (saved_out >= MIN_SAVING_S), retract, 0.0)
    return FastMoves(approach_m=np.asarray(approach, dtype=np.float64),
                     retract_m=np.asarray(retract, dtype=np.float64))


def fast_press(press: Press, settings: ApproachSettings) -> Press:
    """`press` as a two-segment press (its fast moves planned), or unchanged if none is exact."""
    moves = plan_fast_moves(press.distance_m, press.depth_m, press.down_velocity_mps,
                            press.up_velocity_mps, press.acceleration_mps2, settings)
    return replace(
        press, approach_m=float(moves.approach_m[0]), retract_m=float(moves.retract_m[0]),
        travel_velocity_mps=settings.velocity_mps, travel_acceleration_mps2=settings.acceleration_mps2,
    )


def _approach_m(
    d: FloatArray, travel: FloatArray, v: FloatArray, a: FloatArray, settings: ApproachSettings
) -> FloatArray:
    """Where the spec-speed move may start (arm travel from the hover height), unclipped."""
    peak = np.minimum(v, np.sqrt(a * travel))  # a triangle never reaches v
    s_ramp = peak * peak / (2.0 * a)  # distance spent accelerating (= braking)
    t_ramp = peak / a
    t_contact = _time_at(d, travel, peak, s_ramp, t_ramp, a)
    t_keep = t_contact - settings.settle_s  # the spec's motion is kept from here on
    s_keep = _position_at(t_keep, travel, peak, s_ramp, t_ramp, a)
    # Before the braking phase the new move must have reached the cruise speed by s_keep;
    # inside it, the new move is a triangle whose peak is s_keep.
    braking = s_keep > travel - s_ramp
    start = np.where(braking, 2.0 * s_keep - travel, s_keep - v * v / (2.0 * a))
    start = np.where(t_keep > 0.0, start, 0.0)
    start = np.minimum(start, d - settings.clearance_m)
    return np.asarray(np.maximum(start, 0.0), dtype=np.float64)


def _retract_m(
    depth: FloatArray, travel: FloatArray, v_up: FloatArray, a: FloatArray,
    settings: ApproachSettings,
) -> FloatArray:
    """The last stretch of the way up that a fast move may take, unclipped."""
    # The spec's up move must not brake before the fingertip is `clearance_m` above the key's
    # rest surface, i.e. `depth + clearance` above the bottom.
    free = depth + settings.clearance_m
    s_ramp = v_up * v_up / (2.0 * a)
    kept = np.where(free >= s_ramp, free + s_ramp, 2.0 * free)
    return np.asarray(np.maximum(travel - kept, 0.0), dtype=np.float64)


def _moves_s(distance: FloatArray, v: FloatArray, a: FloatArray) -> FloatArray:
    """moveL durations (trapezoid d/v + v/a, or triangle 2·√(d/a))."""
    triangle = distance < v * v / a
    out: FloatArray = np.where(triangle, 2.0 * np.sqrt(np.maximum(distance, 0.0) / a),
                               distance / v + v / a)
    return out


def _fast_s(distance: FloatArray, settings: ApproachSettings) -> FloatArray:
    v = np.full_like(distance, settings.velocity_mps)
    a = np.full_like(distance, settings.acceleration_mps2)
    return _moves_s(distance, v, a)


def _time_at(
    s: FloatArray, travel: FloatArray, peak: FloatArray, s_ramp: FloatArray, t_ramp: FloatArray,
    a: FloatArray,
) -> FloatArray:
    """Time a move (from rest over `travel`) takes to cover `s`."""
    total = 2.0 * t_ramp + (travel - 2.0 * s_ramp) / peak
    out: FloatArray = np.where(
        s <= s_ramp, np.sqrt(2.0 * s / a),
        np.where(s <= travel - s_ramp, t_ramp + (s - s_ramp) / peak,
                 total - np.sqrt(2.0 * np.maximum(travel - s, 0.0) / a)),
    )
    return out


def _position_at(
    t: FloatArray, travel: FloatArray, peak: FloatArray, s_ramp: FloatArray, t_ramp: FloatArray,
    a: FloatArray,
) -> FloatArray:
    """Distance a move (from rest over `travel`) has covered after `t` (clamped to [0, travel])."""
    total = 2.0 * t_ramp + (travel - 2.0 * s_ramp) / peak
    tc = np.clip(t, 0.0, total)
    left = total - tc
    out: FloatArray = np.where(
        tc <= t_ramp, 0.5 * a * tc * tc,
        np.where(left <= t_ramp, travel - 0.5 * a * left * left, s_ramp + peak * (tc - t_ramp)),
    )
    return out
