"""A YAML file that declares the columns of a positional keystroke log.

    # rigid_8col.layout.yaml
    name: rigid-2023-hold-sweep
    finger: rigid                 # soft | rigid | unknown
    columns: [finger_angle_deg, acceleration_mps2, up_acceleration_mps2, down_velocity_mps,
              up_velocity_mps, distance_m, hold_s, depth_m]
    up_travel: distance+depth     # how far the arm rose after the hold (or: depth)

It is validated like an experiment spec: unknown keys, wrong types and unknown column names are
refused with one line naming the file and the YAML path (`layout.yaml: columns[3]`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from pianobot.io.keystroke_layouts import ControlLayout, declared_layout
from pianobot.spec.loader import load_yaml_model


class LayoutFile(BaseModel):
    """The columns of a positional log (`control` list), in order."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field("declared", description="A name for the layout, stored with the run.")
    finger: Literal["soft", "rigid", "unknown"] = Field(
        "unknown",
        description="The finger the log's script drove (a vacuum column decides per line).",
    )
    columns: list[str] = Field(
        min_length=1,
        description="Column names in the order of the control list (pianobot parameter names, "
        "velocity_mps for one speed down and up, note, skip, or a unit-less name for an extra column).",
    )
    up_travel: Literal["distance+depth", "depth"] = Field(
        "distance+depth", description="How far the arm rose after the hold."
    )


def load_layout_file(path: Path | str) -> ControlLayout:
    """The layout a YAML layout file declares; InputError names the file and the YAML path."""
    spec = load_yaml_model(path, LayoutFile)
    return declared_layout(
        spec.columns, spec.finger, spec.name, spec.up_travel, where=f"{path}: columns"
    )
