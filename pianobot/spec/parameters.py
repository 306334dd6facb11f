"""The keystroke parameters a sweep may vary, their defaults, and each finger's safety envelope.

One table, one place: the spec models, the plan's trial columns and the envelope check all read
it. The envelope is the set of ranges that proved safe on the real rig (DESIGN.md); a spec
outside it is refused unless a rig file widens it explicitly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
Finger = Literal["soft", "rigid"]
FINGERS: tuple[Finger, ...] = ("soft", "rigid")

# Tolerance for comparing a value with a range end: YAML and linspace give 0.035000000000000003.
RANGE_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Parameter:
    """One keystroke parameter: name (with unit), meaning, default and physical bounds.

    The bounds say what is physically meaningful for any finger (a speed must be positive);
    the per-finger envelope below says what is safe.
    """

    name: str
    unit: str
    description: str
    default: float | None  # None: must be given (or derived, for the up velocity)
    minimum: float
    maximum: float
    exclusive_minimum: bool = False
    integer: bool = False

    def bounds_text(self) -> str:
        """The physical bounds as text, e.g. `(0, 3] m/s`."""
        left = "(" if self.exclusive_minimum else "["
        return f"{left}{_fmt(self.minimum)}, {_fmt(self.maximum)}] {self.unit}".rstrip()

    def bounds_message(self, value: object) -> str:
        """`must be in (0, 3] m/s, got -1`, with a hint for the usual vacuum sign mistake."""
        whole = "a whole number " if self.integer else ""
        shown = format_value(value) if isinstance(value, int | float) else repr(value)
        hint = ""
        if self.name == "vacuum_kpa" and isinstance(value, int | float) and value > 0:
            hint = " (gauge pressure: a vacuum is negative, e.g. -60)"
        return f"must be {whole}in {self.bounds_text()}{hint}, got {shown}"

    def within_bounds(self, value: float) -> bool:
        """Whether `value` is physically meaningful for this parameter."""
        return bool(self.bounds_mask(np.array([value], dtype=np.float64))[0])

    def bounds_mask(self, values: FloatArray) -> BoolArray:
        """Elementwise `within_bounds` of an array."""
        with np.errstate(invalid="ignore"):
            low_ok = values > self.minimum if self.exclusive_minimum else values >= self.minimum
            ok: BoolArray = np.isfinite(values) & low_ok & (values <= self.maximum)
            if self.integer:
                ok &= np.floor(values) == values
        return ok


PARAMETERS: dict[str, Parameter] = {
    p.name: p
    for p in (
        Parameter("note", "", "MIDI note number of the key pressed (57 = A3).", 57, 21, 108, integer=True),
        Parameter(
            "vacuum_kpa", "kPa",
            "Finger vacuum in kPa gauge (0 = atmospheric, -80 = strong vacuum; the stiffer the "
            "finger, the louder the note). Must be 0 for the rigid finger.",
            0.0, -101.3, 0.0,
        ),
        Parameter(
            "down_velocity_mps", "m/s",
            "Commanded arm speed of the downward moveL (the cruise speed of its trapezoid).",
            None, 0.0, 3.0, exclusive_minimum=True,
        ),
        Parameter(
            "up_velocity_mps", "m/s",
            "Commanded arm speed of the upward moveL; defaults to the down velocity, as in the study.",
            None, 0.0, 3.0, exclusive_minimum=True,
        ),
        Parameter(
            "acceleration_mps2", "m/s²",
            "moveL acceleration (and deceleration) of both moves.",
            0.5, 0.0, 10.0, exclusive_minimum=True,
        ),
        Parameter(
            "depth_m", "m",
            "Pressing depth: how far the arm goes below the point where the fingertip first "
            "touches the resting key.",
            None, 0.0, 0.1,
        ),
        Parameter(
            "distance_m", "m",
            "Key-finger distance: fingertip height above the key surface at the start; the "
            "arm's run-up before contact.",
            0.05, 0.0, 0.3,
        ),
        Parameter("hold_s", "s", "Time the arm stays at its lowest point before moving up.", 0.0, 0.0, 60.0),
        Parameter(
            "finger_angle_deg", "deg",
            "Finger inclination in degrees, as in the study's file names (0 for the rigid finger).",
            0.0, 0.0, 90.0,
        ),
    )
}
PARAMETER_NAMES: tuple[str, ...] = tuple(PARAMETERS)

# The envelope covers the parameters the safety table of DESIGN.md names.
ENVELOPE_PARAMETERS: tuple[str, ...] = (
    "vacuum_kpa",
    "down_velocity_mps",
    "up_velocity_mps",
    "acceleration_mps2",
    "depth_m",
    "distance_m",
    "hold_s",
)


@dataclass(frozen=True)
class Limits:
    """An allowed closed range of one parameter, with where it came from."""

    low: float
    high: float
    source: str = ""  # "" for the built-in envelope, else e.g. "widened by rigs/x.yaml"

    def contains(self, value: float) -> bool:
        """Whether `value` lies in [low, high] (up to float repr noise)."""
        return self.low - RANGE_TOLERANCE <= value <= self.high + RANGE_TOLERANCE

    def mask(self, values: FloatArray) -> BoolArray:
        """Elementwise `contains` of an array."""
        inside: BoolArray = (values >= self.low - RANGE_TOLERANCE) & (
            values <= self.high + RANGE_TOLERANCE
        )
        return inside

    def text(self, unit: str) -> str:
        """The range as text, e.g. `[0.02, 0.035] m`."""
        return f"[{_fmt(self.low)}, {_fmt(self.high)}] {unit}".rstrip()


# Ranges that proved safe on the real rig (DESIGN.md). The rigid finger cannot absorb much
# travel past the key dip (~10 mm), hence its 8-15 mm depth; the soft finger's pad compresses,
# so it presses 20-35 mm (40 mm was recorded but is outside the proven range).
FINGER_ENVELOPES: dict[Finger, dict[str, Limits]] = {
    "rigid": {
        "down_velocity_mps": Limits(0.01, 0.5),
        "up_velocity_mps": Limits(0.01, 0.7),
        "acceleration_mps2": Limits(0.05, 2.0),
        "distance_m": Limits(0.0, 0.05),
        "depth_m": Limits(0.008, 0.015),
        "hold_s": Limits(0.0, 2.0),
        "vacuum_kpa": Limits(0.0, 0.0),  # no vacuum line on the rigid finger
    },
    "soft": {
        "down_velocity_mps": Limits(0.0, 0.06),
        "up_velocity_mps": Limits(0.0, 0.7),
        "acceleration_mps2": Limits(0.05, 2.0),
        "distance_m": Limits(0.0, 0.05),
        "depth_m": Limits(0.020, 0.035),
        "hold_s": Limits(0.0, 2.0),
        "vacuum_kpa": Limits(-80.0, 0.0),
    },
}

# Key travel from rest to the keybed; past it the finger (not the key) absorbs the arm's travel.
KEY_DIP_M = 0.010


def unit_of(name: str) -> str:
    """The unit of a parameter or of any field named with a unit suffix (`settle_s` → s)."""
    if name in PARAMETERS:
        return PARAMETERS[name].unit
    for suffix, unit in _SUFFIX_UNITS:
        if name.endswith(suffix):
            return unit
    return ""


_SUFFIX_UNITS = (
    ("_mps2", "m/s²"),
    ("_mps", "m/s"),
    ("_kpa", "kPa"),
    ("_deg", "deg"),
    ("_hz", "Hz"),
    ("_m", "m"),
    ("_s", "s"),
)


def _fmt(value: float) -> str:
    """A number as short as it reads in a spec: 0.035, -80, 2."""
    if value == int(value) and abs(value) < 1e15:
        return str(int(value))
    return f"{value:.10g}"


def format_value(value: float) -> str:
    """A parameter value for a message (no float repr noise)."""
    return _fmt(value)
