"""One planned keystroke (`Trial`) and the plan as columns or as a table."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields
from operator import attrgetter

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.physics.trajectory import Press
from pianobot.spec import PARAMETER_NAMES

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Trial:
    """One planned keystroke, in run order."""

    trial_id: str  # stable hash of the resolved spec, the parameters and the repeat index
    index: int  # position in the run order, from 0
    repeat: int  # which repetition of its point, from 0
    note: int
    vacuum_kpa: float
    down_velocity_mps: float
    up_velocity_mps: float
    acceleration_mps2: float
    depth_m: float
    distance_m: float
    hold_s: float
    finger_angle_deg: float

    def press(self) -> Press:
        """The arm motion of this trial."""
        return Press(
            distance_m=self.distance_m,
            depth_m=self.depth_m,
            down_velocity_mps=self.down_velocity_mps,
            up_velocity_mps=self.up_velocity_mps,
            acceleration_mps2=self.acceleration_mps2,
            hold_s=self.hold_s,
        )

    def parameters(self) -> dict[str, float]:
        """The keystroke parameters only (the trials table's parameter columns)."""
        return {name: getattr(self, name) for name in PARAMETER_NAMES}

    def row(self) -> dict[str, object]:
        """Column name → value, as in plan.parquet."""
        return asdict(self)


PLAN_COLUMNS: tuple[str, ...] = tuple(f.name for f in fields(Trial))


def trial_columns(trials: Sequence[Trial]) -> dict[str, FloatArray]:
    """Every parameter of `trials` as one float array per name (for vectorised checks)."""
    return {
        name: np.fromiter(map(attrgetter(name), trials), dtype=np.float64, count=len(trials))
        for name in PARAMETER_NAMES
    }


def plan_frame(trials: Sequence[Trial]) -> pd.DataFrame:
    """The plan as a table: one row per trial, columns as in `Trial` (plan.parquet)."""
    frame = pd.DataFrame(
        {name: list(map(attrgetter(name), trials)) for name in PLAN_COLUMNS}, columns=PLAN_COLUMNS
    )
    dtypes = {"trial_id": "string", "index": "int64", "repeat": "int64", "note": "int64"}
    return frame.astype({**{n: "float64" for n in PLAN_COLUMNS}, **dtypes})
