"""The digital piano's readout: two key sensors → note-on velocity, note-off, 1 ms timestamps.

A digital action has no hammer to hear; it times the key between two contacts. The upper sensor
closes first, the lower one near the bottom of the stroke; the note sounds when the lower one
closes, with a velocity from the transit time between them (shorter = louder) mapped through a
monotone curve onto 1–127. The note stops when the key rises back past a release depth. A key
that never reaches the lower sensor is silent — which is what a soft finger at low vacuum or a
shallow press gives. Timestamps are quantised to the 1 ms MIDI clock with a little jitter.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal, overload

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class PianoEvent:
    """One MIDI event the piano sends (times in seconds)."""

    t_s: float
    type: str  # "note_on" | "note_off"
    note: int
    velocity: int


@dataclass(frozen=True)
class PianoParams:
    """Key sensors and velocity curve of a digital piano (depths are key travel, downward).

    The curve maps key speed s (between the sensors) to u = s / full_scale_speed_mps and then
    MIDI velocity round(127·g(u)) clipped to 1–127, with g(u) = u^γ (γ = curve_exponent) or,
    when curve_saturation β > 0, g(u) = tanh(β·u^γ) / tanh(β): monotone, saturating near 127.
    """

    upper_sensor_m: float = 0.0018
    lower_sensor_m: float = 0.0038
    release_m: float = 0.0010
    full_scale_speed_mps: float = 0.06
    curve_exponent: float = 1.0
    curve_saturation: float = 0.0
    timestamp_resolution_s: float = 1e-3
    jitter_s: float = 5e-4

    def __post_init__(self) -> None:
        if not 0.0 < self.upper_sensor_m < self.lower_sensor_m:
            raise ValueError(
                "Sensor depths should satisfy 0 < upper < lower, got "
                f"upper={self.upper_sensor_m}, lower={self.lower_sensor_m}."
            )
        if not 0.0 < self.release_m < self.lower_sensor_m:
            raise ValueError(
                f"release_m should be in (0, {self.lower_sensor_m}), got {self.release_m}."
            )
        for name in ("full_scale_speed_mps", "curve_exponent", "timestamp_resolution_s"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} should be > 0, got {getattr(self, name)}.")
        for name in ("curve_saturation", "jitter_s"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} should be >= 0, got {getattr(self, name)}.")

    def replace(self, **changes: Any) -> PianoParams:
        """A copy with some fields changed."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, float]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> PianoParams:
        """Inverse of `to_dict`; unknown keys raise ValueError naming the known ones."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"unknown piano parameter(s) {unknown}; known: {sorted(known)}.")
        return cls(**{k: float(v) for k, v in data.items()})


@overload
def on_velocity_from_speed(
    speed_mps: float, params: PianoParams, *, rounded: Literal[True] = ..., clipped: bool = ...
) -> int: ...


@overload
def on_velocity_from_speed(
    speed_mps: FloatArray, params: PianoParams, *, rounded: Literal[True] = ..., clipped: bool = ...
) -> npt.NDArray[np.int64]: ...


@overload
def on_velocity_from_speed(
    speed_mps: float, params: PianoParams, *, rounded: Literal[False], clipped: bool = ...
) -> float: ...


@overload
def on_velocity_from_speed(
    speed_mps: FloatArray, params: PianoParams, *, rounded: Literal[False], clipped: bool = ...
) -> FloatArray: ...


def on_velocity_from_speed(
    speed_mps: float | FloatArray, params: PianoParams, *, rounded: bool = True, clipped: bool = True
) -> int | float | npt.NDArray[np.int64] | FloatArray:
    """The piano's velocity curve: MIDI velocity for a key speed between the sensors.

    This is the one implementation of the curve (see `PianoParams`); it is monotone in speed
    and saturating. What the piano sends is the default: rounded to an integer and clipped to
    1–127. `rounded=False` gives the curve before rounding, a smooth function of speed for fits
    and for inverting it (still clipped to [1, 127]); `clipped=False` (with `rounded=False`)
    also drops the clip, for a fit that needs the slope beyond the MIDI range.
    """
    if rounded and not clipped:
        raise ValueError("a rounded MIDI velocity is always clipped to 1-127; pass rounded=False.")
    s = np.asarray(speed_mps, dtype=np.float64)
    u = np.maximum(s, 0.0) / params.full_scale_speed_mps
    g = u**params.curve_exponent
    beta = params.curve_saturation
    if beta > 0.0:
        g = np.tanh(beta * g) / math.tanh(beta)
    velocity = 127.0 * g
    if rounded:
        velocity = np.rint(velocity)
    if clipped:
        velocity = np.clip(velocity, 1.0, 127.0)
    if rounded:
        whole = velocity.astype(np.int64)
        return int(whole) if np.ndim(speed_mps) == 0 else whole
    return float(velocity) if np.ndim(speed_mps) == 0 else np.asarray(velocity, dtype=np.float64)


# Traces longer than this go through the compiled loop (numba, imported on first use: a
# command that never reads a key trace does not pay for it).
_COMPILED_FROM = 64


def _crossing_times(t: FloatArray, x: FloatArray, level: float, downward: bool) -> list[float]:
    """The times x passes `level` (see `_crossings`), interpolated between samples."""
    if x.size > _COMPILED_FROM and t.shape == x.shape:
        # One compiled pass, the same times: the array operations cost more than the arithmetic.
        from pianobot.physics._observe_kernel import crossing_times

        times: list[float] = crossing_times(t, x, float(level), bool(downward)).tolist()
        return times
    k, frac = _crossings(x, level, downward)
    return (t[k - 1] + frac * (t[k] - t[k - 1])).tolist()  # type: ignore[no-any-return]


def _crossings(x: FloatArray, level: float, downward: bool) -> tuple[npt.NDArray[np.intp], FloatArray]:
    """Sample indices k where x passes `level` between k-1 and k, with the fractional position."""
    if downward:
        hit = (x[:-1] < level) & (x[1:] >= level)
    else:
        hit = (x[:-1] > level) & (x[1:] <= level)
    k = np.nonzero(hit)[0] + 1
    frac = (level - x[k - 1]) / (x[k] - x[k - 1])
    return k, frac


def _stamp(t_s: float, params: PianoParams, rng: np.random.Generator | None) -> float:
    """The time the piano reports: jittered (scan + USB latency) and quantised to the MIDI clock."""
    if rng is not None and params.jitter_s > 0.0:
        t_s += float(rng.uniform(0.0, params.jitter_s))
    res = params.timestamp_resolution_s
    return round(math.floor(t_s / res + 0.5) * res, 9)


def key_events(
    t_s: FloatArray, x2_m: FloatArray, params: PianoParams, *, note: int = 57,
    rng: np.random.Generator | None = None,
) -> tuple[list[PianoEvent], float]:
    """Events of one key trace, and the key speed the piano measured for the first note (NaN if silent)."""
    x = np.asarray(x2_m, dtype=np.float64)
    t = np.asarray(t_s, dtype=np.float64)
    marks: list[tuple[float, int]] = []  # (time, kind): 0 upper down, 1 lower down, 2 release up
    for kind, level, down in (
        (0, params.upper_sensor_m, True),
        (1, params.lower_sensor_m, True),
        (2, params.release_m, False),
    ):
        marks.extend((tc, kind) for tc in _crossing_times(t, x, level, down))
    marks.sort()
    events: list[PianoEvent] = []
    first_speed = math.nan
    t_upper: float | None = None
    sounding = False
    gap = params.lower_sensor_m - params.upper_sensor_m
    for tc, kind in marks:
        if kind == 0 and not sounding:
            t_upper = tc
        elif kind == 1 and not sounding and t_upper is not None:
            speed = gap / max(tc - t_upper, 1e-6)
            if math.isnan(first_speed):
                first_speed = speed
            vel = on_velocity_from_speed(speed, params)
            events.append(PianoEvent(_stamp(tc, params, rng), "note_on", note, vel))
            sounding = True
        elif kind == 2:
            if sounding:
                # Off-velocity from the key's rise from the lower sensor depth to release.
                rise = _rise_time(t, x, tc, params)
                off_gap = params.lower_sensor_m - params.release_m
                off_vel = on_velocity_from_speed(off_gap / max(rise, 1e-6), params)
                events.append(PianoEvent(_stamp(tc, params, rng), "note_off", note, off_vel))
                sounding = False
            t_upper = None
    return events, first_speed


def _rise_time(t: FloatArray, x: FloatArray, t_release: float, params: PianoParams) -> float:
    """Time from the key last being at the lower sensor depth to passing the release depth."""
    k_rel = int(np.searchsorted(t, t_release))
    below = np.nonzero(x[:k_rel] >= params.lower_sensor_m)[0]
    if below.size == 0:
        return math.inf
    k = int(below[-1])
    if k + 1 < t.size and x[k + 1] != x[k]:
        frac = (params.lower_sensor_m - x[k]) / (x[k + 1] - x[k])
        t_lower = t[k] + frac * (t[k + 1] - t[k])
    else:
        t_lower = t[k]
    return float(t_release - t_lower)


def piano_events(
    t_s: npt.ArrayLike,
    x2_m: npt.ArrayLike,
    params: PianoParams,
    *,
    note: int = 57,
    rng: np.random.Generator | None = None,
) -> list[list[PianoEvent]]:
    """MIDI events of each key trace (rows of `x2_m`, shape (n, T) or (T,)) on the times `t_s`.

    Crossing times are interpolated between samples; reported times carry the piano's jitter
    (only when `rng` is given) and its 1 ms quantisation. An empty list is a silent keystroke.
    """
    t = np.asarray(t_s, dtype=np.float64)
    x = np.atleast_2d(np.asarray(x2_m, dtype=np.float64))
    if x.shape[1] != t.size:
        raise ValueError(f"x2_m has {x.shape[1]} samples per trace, t_s has {t.size}.")
    return [key_events(t, row, params, note=note, rng=rng)[0] for row in x]
