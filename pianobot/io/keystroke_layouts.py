"""The control-list layouts of positional keystroke logs, and how to tell them apart.

Each line holds `{'control': [...], 'midi': [...]}`; the meaning of `control` depends on the
script that wrote it. Known layouts (slot names carry pianobot's units):

- `soft-2022` (the paper's sweep): [vacuum magnitude kPa, finger angle, acc, vel, depth,
  distance, hold]. The vacuum is stored positive (60 means -60 kPa gauge); the same speed is used
  down and up. `10000` in the vacuum slot marks the rigid finger (no vacuum).
- `rigid-2022` — the rigid finger's logs, three shapes: the paper layout with `10000` in the
  stiffness slot; `rigid-2022-acc` [angle, down acc, up acc, vel, distance, hold] (acceleration
  sweep); `rigid-2022-pretest` [angle, down vel, up vel, distance, hold, acc].
- `sweep-2021` [angle, down vel, up vel, distance, hold] with the acceleration in the header
  dict (`'acc': ...`) that starts each session.

Any other layout is declared by the user (`declared_layout`: a column list, from `--columns`
or a YAML layout file, `layout_file`). Slot names are pianobot's column names (`SLOT_NAMES`) or
the old scripts' names for them (`COLUMN_ALIASES`: vel, acc, depth, hold_time, ...); `skip`
ignores a value, and any other name without a unit suffix keeps the value as an extra column. Layouts the logs do not record (depth in the 5/6-value layouts) are NaN, not guessed.

`auto` and the family name `rigid-2022` choose, among the candidates whose length matches, the
layout under which the largest share of lines has physically plausible values (speeds ≤ 3.2 m/s,
distances ≤ 0.6 m, holds ≤ 10 s, ...); ties go to the earlier layout in `LAYOUTS`.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.errors import InputError
from pianobot.spec.parameters import PARAMETERS

FloatArray = npt.NDArray[np.float64]
RIGID_STIFFNESS_CODE = 10000.0  # the value the study wrote in the vacuum slot for the rigid finger
UP_TRAVELS = ("distance+depth", "depth")
SKIP = "skip"
# What old scripts logged beyond the parameter table: a separate up acceleration and the
# sideways move's speed and acceleration (kept as extra columns of the trials table, in this order).
LOGGED_EXTRAS = ("up_acceleration_mps2", "move_velocity_mps", "move_acceleration_mps2")
# Columns a layout's slot may fill: the parameter table's numbers (the note, a key, is read
# apart) plus what old scripts also logged.
PARAMETER_SLOTS: tuple[str, ...] = (
    *(name for name, p in PARAMETERS.items() if not p.integer), *LOGGED_EXTRAS
)
SLOT_NAMES = (*PARAMETER_SLOTS, "velocity_mps", "note", SKIP)
# The names old scripts used for the same values (named-key logs, and accepted in --columns).
COLUMN_ALIASES: dict[str, str] = {
    "group": "sequence_id",
    "order": "sequence_order",
    "note": "note",
    "down_vel": "down_velocity_mps",
    "up_vel": "up_velocity_mps",
    "vel": "velocity_mps",
    "down_acc": "acceleration_mps2",
    "acc": "acceleration_mps2",
    "up_acc": "up_acceleration_mps2",
    "move_vel": "move_velocity_mps",
    "move_acc": "move_acceleration_mps2",
    "distance": "distance_m",
    "press_depth": "depth_m",
    "depth": "depth_m",
    "hold_time": "hold_s",
    "hold": "hold_s",
    "angle": "finger_angle_deg",
    "finger_angle": "finger_angle_deg",
    "vacuum": "vacuum_kpa",
    "pressure": "vacuum_kpa",
}

_UNIT_SUFFIXES = ("_m", "_s", "_mps", "_mps2", "_kpa", "_deg", "_hz", "_n")


@dataclass(frozen=True)
class ControlLayout:
    """The meaning of each slot of a `control` list.

    `velocity_mps` fills both speeds (the study used one speed down and up); `vacuum_kpa` takes
    the study's convention (a positive magnitude, 60 = -60 kPa gauge; RIGID_STIFFNESS_CODE = rigid
    finger); `up_travel` says how far the arm rose after the hold (for the timing prediction).
    """

    name: str
    slots: tuple[str, ...]
    finger: str  # "soft" | "rigid" | "unknown": the finger the layout's scripts drove
    rigid_code: bool = False  # True: the vacuum slot must hold RIGID_STIFFNESS_CODE
    up_travel: str = "distance+depth"
    declared: bool = False  # declared by the user (not one of the study's layouts)

    @property
    def extra_slots(self) -> tuple[str, ...]:
        return tuple(s for s in self.slots if s not in SLOT_NAMES)

    def table(self, control: FloatArray, header_acc: FloatArray) -> pd.DataFrame:
        """pianobot parameter columns of control lists (one row each; NaN where not logged).

        Args:
            control: (lines, len(slots)) values.
            header_acc: per line, the acceleration of the session's header (NaN: none).
        """
        n = control.shape[0]
        raw = {slot: control[:, i] for i, slot in enumerate(self.slots) if slot != SKIP}
        nan = np.full(n, np.nan)
        out = {name: raw.get(name, nan) for name in PARAMETER_SLOTS}
        for side in ("down_velocity_mps", "up_velocity_mps"):
            if side not in raw and "velocity_mps" in raw:
                out[side] = raw["velocity_mps"]
        acc = out["acceleration_mps2"]
        out["acceleration_mps2"] = np.where(np.isfinite(acc), acc, header_acc)
        if "up_acceleration_mps2" not in raw:
            out["up_acceleration_mps2"] = out["acceleration_mps2"]
        if "vacuum_kpa" in raw:  # stored as a positive magnitude; gauge is <= 0
            stiffness = raw["vacuum_kpa"]
            out["vacuum_kpa"] = np.where(
                stiffness == RIGID_STIFFNESS_CODE, np.nan, -np.abs(stiffness)
            )
        frame = pd.DataFrame(
            {k: round_grid_array(np.asarray(v, dtype=np.float64)) for k, v in out.items()}
        )
        if "note" in raw:
            notes = raw["note"]
            whole = np.isfinite(notes) & (notes == np.round(notes)) & (notes >= 0) & (notes <= 127)
            frame["note"] = pd.array(
                [int(v) if w else None for v, w in zip(notes, whole, strict=True)], dtype="Int64"
            )
        for name in self.extra_slots:
            frame[name] = raw[name]
        return frame

    def fingers(self, control: FloatArray) -> npt.NDArray[np.object_]:
        """Per line: rigid when the stiffness slot holds the rigid code, else the layout's finger."""
        out = np.full(control.shape[0], self.finger, dtype=object)
        if "vacuum_kpa" in self.slots:
            column = control[:, self.slots.index("vacuum_kpa")]
            out[column == RIGID_STIFFNESS_CODE] = "rigid"
            if self.finger == "unknown":
                out[column != RIGID_STIFFNESS_CODE] = "soft"
        return out

    def plausible(self, control: FloatArray) -> npt.NDArray[np.bool_]:
        """Per line: whether every slot holds a physically possible value for its meaning."""
        ok = np.ones(control.shape[0], dtype=bool)
        for i, slot in enumerate(self.slots):
            if slot not in _RANGES:
                continue
            value = control[:, i]
            low, high = _RANGES[slot]
            if slot == "vacuum_kpa":
                rigid = value == RIGID_STIFFNESS_CODE
                ok &= rigid if self.rigid_code else ~rigid
                if self.rigid_code:
                    continue
            inside = (value >= low) & (value <= high)
            if slot in _POSITIVE:
                inside &= value > 0
            ok &= inside
        return ok


_PAPER = (
    "vacuum_kpa",
    "finger_angle_deg",
    "acceleration_mps2",
    "velocity_mps",
    "depth_m",
    "distance_m",
    "hold_s",
)
LAYOUTS: dict[str, ControlLayout] = {
    "soft-2022": ControlLayout("soft-2022", _PAPER, "soft"),
    "rigid-2022": ControlLayout("rigid-2022", _PAPER, "rigid", rigid_code=True),
    "rigid-2022-acc": ControlLayout(
        "rigid-2022-acc",
        (
            "finger_angle_deg",
            "acceleration_mps2",
            "up_acceleration_mps2",
            "velocity_mps",
            "distance_m",
            "hold_s",
        ),
        "rigid",
    ),
    "rigid-2022-pretest": ControlLayout(
        "rigid-2022-pretest",
        (
            "finger_angle_deg",
            "down_velocity_mps",
            "up_velocity_mps",
            "distance_m",
            "hold_s",
            "acceleration_mps2",
        ),
        "rigid",
    ),
    "sweep-2021": ControlLayout(
        "sweep-2021",
        ("finger_angle_deg", "down_velocity_mps", "up_velocity_mps", "distance_m", "hold_s"),
        "soft",
    ),
}
# What the user may ask for: a family name or one concrete layout.
LAYOUT_CHOICES: dict[str, tuple[str, ...]] = {
    "auto": tuple(LAYOUTS),
    "soft-2022": ("soft-2022",),
    "rigid-2022": ("rigid-2022", "rigid-2022-acc", "rigid-2022-pretest"),
    "rigid-2022-acc": ("rigid-2022-acc",),
    "rigid-2022-pretest": ("rigid-2022-pretest",),
    "sweep-2021": ("sweep-2021",),
}

_RANGES: dict[str, tuple[float, float]] = {
    "vacuum_kpa": (0.0, 101.325),  # a magnitude below one atmosphere
    "finger_angle_deg": (-180.0, 180.0),
    "acceleration_mps2": (0.0, 15.0),
    "up_acceleration_mps2": (0.0, 15.0),
    "move_acceleration_mps2": (0.0, 15.0),
    "velocity_mps": (0.0, 3.2),  # UR5 tool speed limit
    "down_velocity_mps": (0.0, 3.2),
    "up_velocity_mps": (0.0, 3.2),
    "move_velocity_mps": (0.0, 3.2),
    "depth_m": (0.0, 0.1),
    "distance_m": (0.0, 0.6),
    "hold_s": (0.0, 10.0),
    "note": (0.0, 127.0),
}
# Speeds and accelerations: a moveL at 0 never happened, so a 0 there means another layout.
_POSITIVE = {
    *(name for name, p in PARAMETERS.items() if p.exclusive_minimum), *LOGGED_EXTRAS, "velocity_mps"
}


def round_grid(value: float) -> float:
    """Drop float repr noise (0.045000000000000005 -> 0.045) while keeping real grid values."""
    if not math.isfinite(value):
        return float(value)
    return float(f"{value:.12g}")


def round_grid_array(values: FloatArray) -> FloatArray:
    """`round_grid` of every value (12 significant digits)."""
    magnitude = np.floor(
        np.log10(np.abs(np.where((values == 0) | ~np.isfinite(values), 1.0, values)))
    )
    k = 11 - magnitude
    with np.errstate(over="ignore", invalid="ignore"):
        scaled = np.where(
            k >= 0,
            np.round(values * 10.0**k) / 10.0**k,
            np.round(values / 10.0 ** (-k)) * 10.0 ** (-k),
        )
    return np.where(np.isfinite(values), scaled, values)


def declared_layout(
    columns: Sequence[str],
    finger: str = "unknown",
    name: str = "declared",
    up_travel: str = "distance+depth",
    where: str = "--columns",
) -> ControlLayout:
    """A user's layout from its column names (validated: known names, no duplicates).

    Raises InputError naming the bad column and, for a near miss, the name that was meant.
    """
    names = [COLUMN_ALIASES.get(c.strip(), c.strip()) for c in columns]
    if not names or any(not c for c in names):
        raise InputError(
            "expected a comma-separated list of column names, e.g. "
            "vacuum_kpa,finger_angle_deg,acceleration_mps2,velocity_mps,depth_m,distance_m,hold_s",
            where,
        )
    for i, column in enumerate(names):
        if column in SLOT_NAMES:
            continue
        close = difflib.get_close_matches(column, [*SLOT_NAMES, *COLUMN_ALIASES], n=1, cutoff=0.75)
        if close or column.endswith(_UNIT_SUFFIXES) or not column.isidentifier():
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise InputError(
                f"column {i + 1} {column!r} is not a known column{hint} Known: {', '.join(SLOT_NAMES)}; "
                "a name without a unit suffix keeps the values as an extra column",
                where,
            )
    taken = [c for c in names if c != SKIP]
    duplicate = next((c for c in taken if taken.count(c) > 1), None)
    if duplicate is not None:
        raise InputError(f"column {duplicate!r} is named twice", where)
    both = {"velocity_mps"} & set(taken) and {"down_velocity_mps", "up_velocity_mps"} & set(taken)
    if both:
        raise InputError(
            "velocity_mps (both speeds) cannot be combined with down/up_velocity_mps", where
        )
    if finger not in ("soft", "rigid", "unknown"):
        raise InputError(f"finger should be soft or rigid, got {finger!r}", where)
    if up_travel not in UP_TRAVELS:
        raise InputError(f"up_travel should be one of {UP_TRAVELS}, got {up_travel!r}", where)
    return ControlLayout(name, tuple(names), finger, up_travel=up_travel, declared=True)


def choose_layout(choice: str, lengths: dict[int, int], plausible: dict[str, int]) -> ControlLayout | None:
    """The candidate layout of `choice` that fits the most control lists plausibly.

    Args:
        choice: a key of LAYOUT_CHOICES.
        lengths: number of control lists of each length.
        plausible: per layout name, how many lines it reads as physically plausible.

    Returns None when no candidate has the length of any control list. A single concrete layout is
    returned as asked (lines of another length are skipped later).
    """
    names = LAYOUT_CHOICES[choice]
    if len(names) == 1:
        return LAYOUTS[names[0]]
    total = max(sum(lengths.values()), 1)
    best: tuple[float, float] | None = None
    chosen: ControlLayout | None = None
    for name in names:
        layout = LAYOUTS[name]
        same_length = lengths.get(len(layout.slots), 0)
        if not same_length:
            continue
        score = (plausible.get(name, 0) / total, same_length / total)
        if best is None or score > best:
            best, chosen = score, layout
    return chosen


def layouts_tried(choice: str) -> str:
    """`soft-2022 (7 values), rigid-2022-acc (6 values), ...` for a refusal message."""
    return ", ".join(f"{n} ({len(LAYOUTS[n].slots)} values)" for n in LAYOUT_CHOICES[choice])
