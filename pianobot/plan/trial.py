"""One planned keystroke (`Trial`) and the plan as columns or as a table."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields
from operator import attrgetter
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from pianobot.physics.trajectory import Press
from pianobot.spec import PARAMETER_NAMES

if TYPE_CHECKING:  # pandas takes a third of a second to import: only where frames are made
    import pandas as pd

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True)  # slots: a million-trial plan is ~4x smaller in memory
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
    # The commanded motion beyond the parameters: a fast approach and retract (spec option
    # `approach: fast`, planned by `plan.approach`); 0 = the spec's two moves only.
    approach_m: float = 0.0
    retract_m: float = 0.0
    travel_velocity_mps: float = 0.25
    travel_acceleration_mps2: float = 1.0

    def press(self) -> Press:
        """The arm motion of this trial."""
        return Press(
            distance_m=self.distance_m,
            depth_m=self.depth_m,
            down_velocity_mps=self.down_velocity_mps,
            up_velocity_mps=self.up_velocity_mps,
            acceleration_mps2=self.acceleration_mps2,
            hold_s=self.hold_s,
            approach_m=self.approach_m,
            retract_m=self.retract_m,
            travel_velocity_mps=self.travel_velocity_mps,
            travel_acceleration_mps2=self.travel_acceleration_mps2,
        )

    def parameters(self) -> dict[str, float]:
        """The keystroke parameters only (the trials table's parameter columns)."""
        return {name: getattr(self, name) for name in PARAMETER_NAMES}

    def row(self) -> dict[str, object]:
        """Column name → value, as in plan.parquet (motion columns only with a fast move)."""
        row = asdict(self)
        if not (self.approach_m > 0.0 or self.retract_m > 0.0):
            for name in MOTION_COLUMNS:
                del row[name]
        return row


# The commanded fast moves of a two-segment press: plan.parquet columns after the parameters,
# present only in the plan of a sweep with `approach: fast`.
MOTION_COLUMNS: tuple[str, ...] = (
    "approach_m", "retract_m", "travel_velocity_mps", "travel_acceleration_mps2",
)
PLAN_COLUMNS: tuple[str, ...] = tuple(f.name for f in fields(Trial) if f.name not in MOTION_COLUMNS)
FAST_PLAN_COLUMNS: tuple[str, ...] = PLAN_COLUMNS + MOTION_COLUMNS


def trial_columns(
    trials: Sequence[Trial], names: Sequence[str] = PARAMETER_NAMES
) -> dict[str, FloatArray]:
    """Every parameter (or other named field) of `trials` as one float array per name."""
    return {
        name: np.fromiter(map(attrgetter(name), trials), dtype=np.float64, count=len(trials))
        for name in names
    }


def plan_frame(trials: Sequence[Trial]) -> pd.DataFrame:
    """The plan as a table: one row per trial, columns as in `Trial` (plan.parquet).

    The motion columns (`MOTION_COLUMNS`) are there only when some trial has a fast move, so
    the plan of an as-specified sweep reads as it always did.
    """
    import pandas as pd

    fast = any(t.approach_m > 0.0 or t.retract_m > 0.0 for t in trials)
    columns = FAST_PLAN_COLUMNS if fast else PLAN_COLUMNS
    frame = pd.DataFrame(
        {name: list(map(attrgetter(name), trials)) for name in columns}, columns=columns
    )
    dtypes = {"trial_id": "string", "index": "int64", "repeat": "int64", "note": "int64"}
    return frame.astype({**{n: "float64" for n in columns}, **dtypes})
