"""The control-list layouts of the study's keystroke logs, and how to tell them apart.

Each log line holds `{'control': [...], 'midi': [...]}`; the meaning of `control` depends on the
script that wrote it. Known layouts (slot names carry pianobot's units):

- `soft-2022` (the paper's sweep): [vacuum magnitude kPa, finger angle, acc, vel, depth,
  distance, hold]. The vacuum is stored positive (60 means -60 kPa gauge); the same speed is used
  down and up. `10000` in the vacuum slot marks the rigid finger (no vacuum).
- `rigid-2022` — the rigid finger's logs, three shapes: the paper layout with `10000` in the
  stiffness slot; `rigid-2022-acc` [angle, down acc, up acc, vel, distance, hold] (acceleration
  sweep); `rigid-2022-pretest` [angle, down vel, up vel, distance, hold, acc].
- `sweep-2021` [angle, down vel, up vel, distance, hold] with the acceleration in the header
  dict (`'acc': ...`) that starts each session.

Layouts the logs do not record (depth in the 5/6-value layouts) are NaN, not guessed.
`auto` and the family name `rigid-2022` choose, among the candidates whose length matches, the
layout under which the largest share of lines has physically plausible values (speeds ≤ 3.2 m/s,
distances ≤ 0.6 m, holds ≤ 10 s, ...); ties go to the earlier layout in `LAYOUTS`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

RIGID_STIFFNESS_CODE = 10000.0  # the value the study wrote in the vacuum slot for the rigid finger


@dataclass(frozen=True)
class Layout:
    """The meaning of each slot of a `control` list."""

    name: str
    slots: tuple[str, ...]
    finger: str  # "soft" | "rigid": the finger the layout's scripts drove
    rigid_code: bool = False  # True: the vacuum slot must hold RIGID_STIFFNESS_CODE

    def params(self, control: Sequence[float], header_acc: float | None) -> dict[str, float]:
        """pianobot parameters of one control list (units in the names, NaN where not logged)."""
        raw = dict(zip(self.slots, control, strict=True))
        out = {
            "vacuum_kpa": math.nan,
            "finger_angle_deg": raw.get("finger_angle_deg", math.nan),
            "acceleration_mps2": raw.get("acceleration_mps2", math.nan),
            "up_acceleration_mps2": math.nan,
            "down_velocity_mps": raw.get("down_velocity_mps", raw.get("velocity_mps", math.nan)),
            "up_velocity_mps": raw.get("up_velocity_mps", raw.get("velocity_mps", math.nan)),
            "depth_m": raw.get("depth_m", math.nan),
            "distance_m": raw.get("distance_m", math.nan),
            "hold_s": raw.get("hold_s", math.nan),
        }
        if math.isnan(out["acceleration_mps2"]) and header_acc is not None:
            out["acceleration_mps2"] = header_acc
        out["up_acceleration_mps2"] = raw.get("up_acceleration_mps2", out["acceleration_mps2"])
        stiffness = raw.get("vacuum_kpa")
        if stiffness is not None and stiffness != RIGID_STIFFNESS_CODE:
            out["vacuum_kpa"] = -abs(stiffness)  # stored as a positive magnitude; gauge is <= 0
        return {k: round_grid(v) for k, v in out.items()}

    def finger_of(self, control: Sequence[float]) -> str:
        """The finger: rigid when the stiffness slot holds the rigid code, else the layout's."""
        if (
            "vacuum_kpa" in self.slots
            and control[self.slots.index("vacuum_kpa")] == RIGID_STIFFNESS_CODE
        ):
            return "rigid"
        return self.finger

    def plausible(self, control: Sequence[float]) -> bool:
        """Whether every slot holds a physically possible value for its meaning."""
        if len(control) != len(self.slots):
            return False
        for slot, value in zip(self.slots, control, strict=True):
            low, high = _RANGES[slot]
            if slot == "vacuum_kpa":
                if self.rigid_code != (value == RIGID_STIFFNESS_CODE):
                    return False
                if self.rigid_code:
                    continue
            if not (low <= value <= high) or (slot in _POSITIVE and value <= 0):
                return False
        return True


_PAPER = (
    "vacuum_kpa",
    "finger_angle_deg",
    "acceleration_mps2",
    "velocity_mps",
    "depth_m",
    "distance_m",
    "hold_s",
)
LAYOUTS: dict[str, Layout] = {
    "soft-2022": Layout("soft-2022", _PAPER, "soft"),
    "rigid-2022": Layout("rigid-2022", _PAPER, "rigid", rigid_code=True),
    "rigid-2022-acc": Layout(
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
    "rigid-2022-pretest": Layout(
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
    "sweep-2021": Layout(
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
    "velocity_mps": (0.0, 3.2),  # UR5 tool speed limit
    "down_velocity_mps": (0.0, 3.2),
    "up_velocity_mps": (0.0, 3.2),
    "depth_m": (0.0, 0.1),
    "distance_m": (0.0, 0.6),
    "hold_s": (0.0, 10.0),
}
_POSITIVE = {
    "acceleration_mps2",
    "up_acceleration_mps2",
    "velocity_mps",
    "down_velocity_mps",
    "up_velocity_mps",
}


def round_grid(value: float) -> float:
    """Drop float repr noise (0.045000000000000005 -> 0.045) while keeping real grid values."""
    if not math.isfinite(value):
        return float(value)
    return float(f"{value:.12g}")


def choose_layout(choice: str, controls: Sequence[Sequence[float]]) -> Layout | None:
    """The candidate layout of `choice` that fits the most control lists plausibly.

    Returns None when no candidate has the length of any control list. A single concrete layout is
    returned as asked (lines of another length are skipped later).
    """
    names = LAYOUT_CHOICES[choice]
    if len(names) == 1:
        return LAYOUTS[names[0]]
    best: tuple[float, float] | None = None
    chosen: Layout | None = None
    for name in names:
        layout = LAYOUTS[name]
        same_length = [c for c in controls if len(c) == len(layout.slots)]
        if not same_length:
            continue
        plausible = sum(layout.plausible(c) for c in same_length)
        score = (plausible / len(controls), len(same_length) / len(controls))
        if best is None or score > best:
            best, chosen = score, layout
    return chosen
