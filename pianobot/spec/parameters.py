"""The keystroke parameters a sweep may vary, their defaults, and each finger's safety envelope.

One table, one place (`PARAMETERS`): the spec's models and its `ParameterName`, the plan's trial
columns and trial ids, the trials table's Parquet columns, the predictors' inputs, the arm's
`Press` (`plan.trial.press_from`), the progress line, figure labels and the envelope check all
read it; a test (tests/spec/test_parameter_table.py) fails when a list of parameter names is
written out anywhere else. Each default carries its reason. The envelope is the set of ranges
that proved safe on the real rig (DESIGN.md); a spec outside it is refused unless a rig file
widens it explicitly.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal, TypeVar

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
T = TypeVar("T")
Finger = Literal["soft", "rigid"]
FINGERS: tuple[Finger, ...] = ("soft", "rigid")

# Tolerance for comparing a value with a range end: YAML and linspace give 0.035000000000000003.
RANGE_TOLERANCE = 1e-9


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


@dataclass(frozen=True)
class Parameter:
    """One keystroke parameter: name (with unit), meaning, default and physical bounds.

    The bounds say what is physically meaningful for any finger (a speed must be positive);
    `safe` says what proved safe per finger (the envelope). The remaining fields say where the
    parameter appears: in the arm's `Press`, in a predictor's inputs, in the progress line.
    """

    name: str
    unit: str
    description: str
    default: float | None  # None: must be given, or follows another parameter (`follows`)
    minimum: float
    maximum: float
    exclusive_minimum: bool = False
    integer: bool = False
    default_reason: str = ""  # why the default is what it is
    follows: str | None = None  # when not given, takes this parameter's value (per trial)
    model_default: float | None = None  # a model's stand-in when a caller gives no value and
    #                                     there is no default (`input_default`)
    press: bool = False  # a field of the arm's motion (`physics.trajectory.Press`)
    safe: dict[Finger, Limits] | None = None  # the proven-safe range per finger (DESIGN.md)
    label: str = ""  # how figures and tables name it
    display_unit: str = ""  # the unit it is shown in (lengths and speeds in mm)
    display_scale: float = 1.0  # SI value × scale = shown value
    in_progress: bool = False  # shown in the progress line of a running sweep

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


# The safe ranges (DESIGN.md) proved on the real rig. The rigid finger cannot absorb much
# travel past the key dip (~10 mm), hence its 8-15 mm depth; the soft finger's pad compresses,
# so it presses 20-35 mm (40 mm was recorded but is outside the proven range).
def _safe(rigid: tuple[float, float], soft: tuple[float, float]) -> dict[Finger, Limits]:
    return {"rigid": Limits(*rigid), "soft": Limits(*soft)}


# The order of this table is the order of the trials table's columns and of the values hashed
# into trial ids: never reorder it, only append.
PARAMETERS: dict[str, Parameter] = {
    p.name: p
    for p in (
        Parameter(
            "note", "", "MIDI note number of the key pressed (57 = A3).", 57, 21, 108, integer=True,
            default_reason="the key the study pressed (A3); a spec's `note:` overrides it",
            label="MIDI note",
        ),
        Parameter(
            "vacuum_kpa", "kPa",
            "Finger vacuum in kPa gauge (0 = atmospheric, -80 = strong vacuum; the stiffer the "
            "finger, the louder the note). Must be 0 for the rigid finger.",
            0.0, -101.3, 0.0,
            default_reason="no vacuum: the only value the rigid finger allows, the softest soft finger",
            safe=_safe((0.0, 0.0), (-80.0, 0.0)),  # no vacuum line on the rigid finger
            label="vacuum", display_unit="kPa", in_progress=True,
        ),
        Parameter(
            "down_velocity_mps", "m/s",
            "Commanded arm speed of the downward moveL (the cruise speed of its trapezoid).",
            None, 0.0, 3.0, exclusive_minimum=True,
            default_reason="none: the loudness depends on it most, so a sweep must say",
            press=True, safe=_safe((0.01, 0.5), (0.0, 0.06)),
            label="arm down velocity", display_unit="mm/s", display_scale=1e3, in_progress=True,
        ),
        Parameter(
            "up_velocity_mps", "m/s",
            "Commanded arm speed of the upward moveL; defaults to the down velocity, as in the study.",
            None, 0.0, 3.0, exclusive_minimum=True,
            default_reason="the down velocity of the same trial: the study moved up as fast as down",
            follows="down_velocity_mps",
            press=True, safe=_safe((0.01, 0.7), (0.0, 0.7)),
            label="arm up velocity", display_unit="mm/s", display_scale=1e3,
        ),
        Parameter(
            "acceleration_mps2", "m/s²",
            "moveL acceleration (and deceleration) of both moves.",
            0.5, 0.0, 10.0, exclusive_minimum=True,
            default_reason="the middle level of the study's acceleration grid (0.1, 0.5, 1 m/s²), "
            "inside both fingers' envelope (0.05-2 m/s²)",
            press=True, safe=_safe((0.05, 2.0), (0.05, 2.0)),
            label="arm acceleration", display_unit="mm/s²", display_scale=1e3, in_progress=True,
        ),
        Parameter(
            "depth_m", "m",
            "Pressing depth: how far the arm goes below the point where the fingertip first "
            "touches the resting key.",
            None, 0.0, 0.1,
            default_reason="none: the safe depth differs per finger (8-15 mm rigid, 20-35 mm soft)",
            model_default=0.03,  # a soft-finger press inside its 20-35 mm envelope
            press=True, safe=_safe((0.008, 0.015), (0.020, 0.035)),
            label="pressing depth", display_unit="mm", display_scale=1e3, in_progress=True,
        ),
        Parameter(
            "distance_m", "m",
            "Key-finger distance: fingertip height above the key surface at the start; the "
            "arm's run-up before contact.",
            0.05, 0.0, 0.3,
            default_reason="the study's run-up: the top of both fingers' envelope (0-50 mm)",
            press=True, safe=_safe((0.0, 0.05), (0.0, 0.05)),
            label="finger–key distance", display_unit="mm", display_scale=1e3,
        ),
        Parameter(
            "hold_s", "s", "Time the arm stays at its lowest point before moving up.", 0.0, 0.0, 60.0,
            default_reason="no dwell: the study moved up as soon as it reached the depth",
            press=True, safe=_safe((0.0, 2.0), (0.0, 2.0)),
            label="hold", display_unit="s",
        ),
        Parameter(
            "finger_angle_deg", "deg",
            "Finger inclination in degrees, as in the study's file names (0 for the rigid finger).",
            0.0, 0.0, 90.0,
            default_reason="upright: the rigid finger's only angle",
            label="finger angle", display_unit="°",
        ),
    )
}
PARAMETER_NAMES: tuple[str, ...] = tuple(PARAMETERS)
# The parameters a finger's envelope covers (the safety table of DESIGN.md), table order.
ENVELOPE_PARAMETERS: tuple[str, ...] = tuple(n for n, p in PARAMETERS.items() if p.safe is not None)
# The parameters of the arm's motion (`Press`), table order.
PRESS_PARAMETERS: tuple[str, ...] = tuple(n for n, p in PARAMETERS.items() if p.press)
# What a stroke predictor reads: the arm's motion and the finger's vacuum (what the physics
# depends on); the note and the finger angle only label a keystroke.
PREDICTOR_INPUTS: tuple[str, ...] = ENVELOPE_PARAMETERS
# What a sweep must give: no default and nothing to follow.
REQUIRED_PARAMETERS: tuple[str, ...] = tuple(
    n for n, p in PARAMETERS.items() if p.default is None and p.follows is None
)
FINGER_ENVELOPES: dict[Finger, dict[str, Limits]] = {
    finger: {n: p.safe[finger] for n, p in PARAMETERS.items() if p.safe is not None}
    for finger in ("rigid", "soft")  # rigid first: a depth in both ranges reads as rigid
}


def missing_value(name: str, given: Mapping[str, T]) -> T | float | None:
    """The value `name` takes when it is not given: the value it follows (up velocity → the
    down velocity in `given`), else its default; None when it must be given.

    Works on scalars, arrays and columns alike (a followed value is returned as given).
    """
    p = PARAMETERS[name]
    if p.follows is not None and p.follows in given:
        return given[p.follows]
    return p.default


def defaults_text() -> str:
    """The defaults a sweep's unset parameters take, for help texts: `distance 0.05 m, ...`."""
    parts = []
    for p in PARAMETERS.values():
        words = p.label.removeprefix("arm ") or p.name
        if p.follows is not None:
            parts.append(f"{words} = {PARAMETERS[p.follows].label.removeprefix('arm ')}")
        elif p.default is not None and p.name != "note":  # the spec's own `note:` sets the note
            parts.append(f"{words} {_fmt(p.default)} {p.unit}".rstrip())
    return ", ".join(parts)


def recorded_or_followed(name: str, columns: Mapping[str, FloatArray]) -> FloatArray:
    """`columns[name]` where it holds a value, else the column it follows (up velocity → down
    velocity): a log's unrecorded (NaN) or impossible (at or below an exclusive minimum, a
    moveL at 0 m/s) entries.
    """
    own = np.asarray(columns[name], dtype=np.float64)
    p = PARAMETERS[name]
    if p.follows is None or p.follows not in columns:
        return own
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(own) & ((own > p.minimum) if p.exclusive_minimum else True)
    return np.where(valid, own, np.asarray(columns[p.follows], dtype=np.float64))


def input_default(name: str) -> float | None:
    """What a model assumes for an input a caller leaves out: the default, else the model's
    stand-in (a depth inside the soft finger's envelope); None for the down velocity."""
    p = PARAMETERS[name]
    return p.default if p.default is not None else p.model_default


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
