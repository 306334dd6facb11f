"""The truth lab's digital piano: two key contacts → note-on velocity; note-off at a release depth.

The action closes an upper contact, then a lower one near the bottom of the stroke. The note
sounds when the lower contact closes; the piano times the key between the two contacts and maps
that transit speed through its velocity curve onto 1–127. The note stops when the rising key
passes the release depth (the off velocity comes from the rise time from the lower contact to
the release depth). A key that never closes the lower contact is silent. The contacts re-arm
only once the key is back above the upper one, so a key that bounces below it cannot strike
twice, but one that rises and falls again can.

Velocity curves (u = transit speed / full-scale speed):
- linear: 127·u (the base piano),
- tanh: 127·tanh(β·u^γ)/tanh(β) (the shape pianobot's `velocity_curve` candidate has),
- rational: 127·u·(1 + κ)/(u + κ) (saturating with another shape).
Every curve is clipped to 1–127 and rounded; all are monotone in the speed.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
CURVES = ("linear", "tanh", "rational")


@dataclass(frozen=True)
class VelocityCurve:
    """Transit speed → MIDI velocity (see module docstring)."""

    kind: str = "linear"
    exponent: float = 1.0  # tanh: γ
    saturation: float = 0.0  # tanh: β
    knee: float = 0.0  # rational: κ

    def __post_init__(self) -> None:
        if self.kind not in CURVES:
            raise ValueError(f"velocity curve should be one of {CURVES}, got {self.kind!r}")

    def shape(self, u: float) -> float:
        """The curve before scaling to 127 (0 at u = 0, 1 at u = 1)."""
        u = max(u, 0.0)
        if self.kind == "tanh":
            return math.tanh(self.saturation * u**self.exponent) / math.tanh(self.saturation)
        if self.kind == "rational":
            return u * (1.0 + self.knee) / (u + self.knee)
        return u

    def velocity(self, speed_mps: float, full_scale_mps: float) -> int:
        value = 127.0 * self.shape(speed_mps / full_scale_mps)
        return int(min(127, max(1, round(value))))


@dataclass(frozen=True)
class Piano:
    """Contact depths (key travel, m), curve, and the MIDI clock's latency and jitter."""

    upper_m: float = 0.0016
    lower_m: float = 0.0046
    release_m: float = 0.0027
    full_scale_mps: float = 0.08
    off_full_scale_mps: float = 0.30
    latency_s: float = 0.0025
    jitter_s: float = 0.0004
    note: int = 57
    curve: VelocityCurve = field(default_factory=VelocityCurve)

    def __post_init__(self) -> None:
        if not 0.0 < self.upper_m < self.release_m < self.lower_m:
            raise ValueError(
                "contacts should satisfy 0 < upper < release < lower, got "
                f"{self.upper_m}, {self.release_m}, {self.lower_m}"
            )

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


@dataclass(frozen=True)
class NoteEvent:
    """One MIDI event relative to the keystroke's motion start (seconds, not yet quantised)."""

    t_s: float
    kind: str  # "note_on" | "note_off"
    velocity: int
    speed_mps: float  # the transit speed the piano measured


def _crossings(t: FloatArray, x: FloatArray, level: float) -> tuple[FloatArray, FloatArray]:
    """Times where x crosses `level` downward (+) and upward (−), by linear interpolation."""
    above = x >= level
    idx = np.flatnonzero(above[1:] != above[:-1])
    frac = (level - x[idx]) / (x[idx + 1] - x[idx])
    times = t[idx] + frac * (t[idx + 1] - t[idx])
    direction = np.where(above[idx + 1], 1.0, -1.0)
    return times, direction


def read_key(piano: Piano, t_s: FloatArray, x2_m: FloatArray) -> list[NoteEvent]:
    """The events the piano sends for one key trajectory (key travel x2, downward positive)."""
    marks: list[tuple[float, str, float]] = []
    for name, level in (("upper", piano.upper_m), ("lower", piano.lower_m),
                        ("release", piano.release_m)):  # fmt: skip
        times, direction = _crossings(t_s, x2_m, level)
        marks.extend((float(tt), name, float(d)) for tt, d in zip(times, direction, strict=True))
    marks.sort()
    events: list[NoteEvent] = []
    armed, sounding = True, False
    t_upper = math.nan
    t_lower_up = math.nan
    for t, name, direction in marks:
        if name == "upper" and direction > 0:
            t_upper = t
        elif name == "upper" and direction < 0 and not sounding:
            armed = True
        elif name == "lower" and direction > 0 and armed:
            transit = t - t_upper if math.isfinite(t_upper) else math.inf
            speed = (piano.lower_m - piano.upper_m) / transit if transit > 0 else math.inf
            vel = piano.curve.velocity(speed, piano.full_scale_mps)
            events.append(NoteEvent(t + piano.latency_s, "note_on", vel, speed))
            armed, sounding = False, True
        elif name == "lower" and direction < 0:
            t_lower_up = t
        elif name == "release" and direction < 0 and sounding:
            rise = t - t_lower_up if math.isfinite(t_lower_up) else math.inf
            speed = (piano.lower_m - piano.release_m) / rise if rise > 0 else 0.0
            vel = VelocityCurve().velocity(speed, piano.off_full_scale_mps)
            events.append(NoteEvent(t + piano.latency_s, "note_off", vel, speed))
            sounding = False
    return events
