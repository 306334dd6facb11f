"""The interface `play` uses to choose strokes: control parameters in, MIDI outcome out.

A `StrokePredictor` maps press parameters (vacuum, down velocity, acceleration, depth, distance,
hold, up velocity) to the expected MIDI outcome: on-velocity, probability of a silent keystroke,
the lead time from motion start to note-on and the MIDI hold time. Its `inverse` answers the
question `play` asks per note: "which down velocity gives on-velocity v here?".

Implementations: `PhysicsPredictor` (simulates the physical model over a grid of presses and
interpolates; `PhysicsPredictor.published()` is the default when no model file is given) and the
learned predictors written by `pianobot fit` (`pianobot.analysis.learn`). `load_predictor(path)`
opens either kind by looking at the file's schema tag.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt
import pandas as pd

FloatArray = npt.NDArray[np.float64]

#: Columns a predictor reads (missing ones take `DEFAULT_INPUTS`).
INPUT_COLUMNS: tuple[str, ...] = (
    "vacuum_kpa",
    "down_velocity_mps",
    "acceleration_mps2",
    "depth_m",
    "distance_m",
    "hold_s",
    "up_velocity_mps",
)
#: Columns every predictor returns, in this order.
OUTPUT_COLUMNS: tuple[str, ...] = ("on_velocity", "p_silent", "lead_s", "midi_hold_s")

#: Values used for inputs a caller leaves out (the study's fixed settings).
DEFAULT_INPUTS: dict[str, float] = {
    "vacuum_kpa": 0.0,
    "acceleration_mps2": 1.0,
    "depth_m": 0.03,
    "distance_m": 0.05,
    "hold_s": 0.0,
}


@runtime_checkable
class StrokePredictor(Protocol):
    """Forward and inverse map between press parameters and the MIDI outcome of one keystroke."""

    def predict(self, frame: pd.DataFrame) -> pd.DataFrame:
        """Outcome per row: `on_velocity` (1–127, NaN when silent is likely), `p_silent` (0–1),
        `lead_s` (motion start → note-on), `midi_hold_s` (note-on → note-off)."""
        ...

    def inverse(
        self,
        target_on_velocity: npt.ArrayLike,
        *,
        vacuum_kpa: float,
        acceleration_mps2: float,
        depth_m: float,
        distance_m: float,
    ) -> FloatArray:
        """Down velocity (m/s) that yields each target on-velocity; NaN where unreachable."""
        ...

    def velocity_range(
        self,
        *,
        vacuum_kpa: float,
        acceleration_mps2: float,
        depth_m: float,
        distance_m: float,
        max_down_velocity_mps: float,
    ) -> tuple[float, float]:
        """The lowest and highest sounding on-velocity reachable with down velocity ≤ the cap."""
        ...


def complete_inputs(frame: pd.DataFrame) -> pd.DataFrame:
    """The input columns of `frame` with defaults filled in (up velocity defaults to down)."""
    if "down_velocity_mps" not in frame.columns:
        from pianobot.errors import InputError

        raise InputError("a predictor needs the column down_velocity_mps", "predict")
    out = pd.DataFrame(index=frame.index)
    for name in INPUT_COLUMNS:
        if name in frame.columns:
            out[name] = frame[name].astype(float)
        elif name == "up_velocity_mps":
            out[name] = frame["down_velocity_mps"].astype(float)
        else:
            out[name] = DEFAULT_INPUTS[name]
    return out
