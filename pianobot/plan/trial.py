"""One planned keystroke (`Trial`), the arm motion of any named parameters (`press_from`), and
the plan as columns or as a table.

`press_from(mapping)` is the one place a `Press` is built from parameter values by name: a
trial, a row of a trials table, a predictor's input row, a play stroke. A value not given takes
what the parameter table says (`spec.parameters.missing_value`: the up velocity follows the down
velocity, the others their defaults). `trial_from` builds a `Trial` by name the same way.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, fields
from operator import attrgetter
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from pianobot.physics.trajectory import Press
from pianobot.spec.parameters import PARAMETER_NAMES, PARAMETERS, PRESS_PARAMETERS, missing_value

if TYPE_CHECKING:  # pandas takes a third of a second to import: only where frames are made
    import pandas as pd

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True)  # slots: a million-trial plan is ~4x smaller in memory
class Trial:
    """One planned keystroke, in run order.

    The parameter fields are the parameter table's names in its order (`PARAMETER_NAMES`: a
    test keeps them equal); build one by name with `trial_from`.
    """

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
        return press_from({name: getattr(self, name) for name in PRESS_FIELDS})

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


@dataclass(frozen=True, slots=True)
class SequenceTrial(Trial):
    """A keystroke of a sequence sweep: a `Trial` that also knows its sequence and its place
    in it (plan and trials columns `SEQUENCE_COLUMNS`; other sweeps' plans do not have them)."""

    sequence_id: int = 0
    sequence_order: int = 0


# The commanded fast moves of a two-segment press: plan.parquet columns after the parameters,
# present only in the plan of a sweep with `approach: fast`.
MOTION_COLUMNS: tuple[str, ...] = (
    "approach_m", "retract_m", "travel_velocity_mps", "travel_acceleration_mps2",
)
# A sequence sweep's trials: which sequence, and the place in it (from 0).
SEQUENCE_COLUMNS: tuple[str, ...] = ("sequence_id", "sequence_order")
PLAN_COLUMNS: tuple[str, ...] = tuple(f.name for f in fields(Trial) if f.name not in MOTION_COLUMNS)
FAST_PLAN_COLUMNS: tuple[str, ...] = PLAN_COLUMNS + MOTION_COLUMNS
# Everything `press_from` reads: the motion parameters, then the commanded fast moves.
PRESS_FIELDS: tuple[str, ...] = PRESS_PARAMETERS + MOTION_COLUMNS


def given(values: Mapping[Any, Any], name: str) -> bool:
    """Whether `values` gives `name` (None or NaN, as a table shows a value not logged, does not)."""
    value = values.get(name)
    return value is not None and value == value  # NaN is the one value unequal to itself


def completed(values: Mapping[Any, Any], names: Sequence[str]) -> dict[str, Any]:
    """`values` of `names`, each not given taken from the parameter table (`missing_value`).

    Raises:
        ValueError: a parameter that must be given (down velocity, depth) is not.
    """
    out: dict[str, Any] = {}
    missing: list[str] = []
    for name in names:
        value = values.get(name)
        if value is None or value != value:  # None or NaN: not given (inlined: the hot path)
            missing.append(name)
        else:
            out[name] = value
    for name in missing:
        if name not in PARAMETERS:
            continue
        followed = PARAMETERS[name].follows
        known = dict(out)
        if followed is not None and followed not in known and given(values, followed):
            known[followed] = values[followed]  # (a followed value outside `names`)
        value = missing_value(name, known)
        if value is None:
            raise ValueError(f"{name} is not given and has no default")
        out[name] = value
    return out


def press_from(values: Mapping[Any, Any]) -> Press:
    """The arm motion of parameter values given by name (a dict, a table row, a trial's fields).

    Motion parameters not given take the parameter table's defaults (the up velocity follows
    the down velocity); the fast-move fields (`MOTION_COLUMNS`) are read when present.

    Raises:
        ValueError: the down velocity or the depth is not given.
    """
    motion: dict[str, float] = {}
    for name in PRESS_PARAMETERS:  # every parameter given (a trial, a table row): no defaults to look up
        value = values.get(name)
        if value is None or value != value:
            return Press(**{name: float(v) for name, v in completed(values, PRESS_FIELDS).items()})
        motion[name] = float(value)
    for name in MOTION_COLUMNS:  # fast-move fields have no table default: Press's own when not given
        value = values.get(name)
        if value is not None and value == value:
            motion[name] = float(value)
    return Press(**motion)


def trial_from(trial_id: str, index: int, repeat: int, values: Mapping[Any, Any]) -> Trial:
    """A `Trial` from parameter values by name (defaults as in `press_from`; fast-move fields
    optional).

    Raises:
        ValueError: the down velocity or the depth is not given.
    """
    present = completed(values, PARAMETER_NAMES + MOTION_COLUMNS)
    numbers: dict[str, Any] = {
        name: int(v) if name in PARAMETERS and PARAMETERS[name].integer else float(v)
        for name, v in present.items()
    }
    return Trial(trial_id, index, repeat, **numbers)


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

    The motion columns (`MOTION_COLUMNS`) are there only when some trial has a fast move, and
    the sequence columns (`SEQUENCE_COLUMNS`) only in a sequence sweep's plan, so the plan of
    any other sweep reads as it always did.
    """
    import pandas as pd

    fast = any(t.approach_m > 0.0 or t.retract_m > 0.0 for t in trials)
    columns = FAST_PLAN_COLUMNS if fast else PLAN_COLUMNS
    if trials and all(isinstance(t, SequenceTrial) for t in trials):
        columns = columns + SEQUENCE_COLUMNS
    frame = pd.DataFrame(
        {name: list(map(attrgetter(name), trials)) for name in columns}, columns=columns
    )
    dtypes = {"trial_id": "string", "index": "int64", "repeat": "int64", "note": "int64",
              **{name: "int64" for name in SEQUENCE_COLUMNS if name in columns}}
    return frame.astype({**{n: "float64" for n in columns}, **dtypes})
