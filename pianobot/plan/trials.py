"""Expand a spec into the exact list of trials that will run: pure, deterministic, persisted first.

`expand(spec)` turns a grid, random or Latin-hypercube sweep into `Trial`s in run order, each
with a stable `trial_id`: a hash of the resolved spec, the trial's parameters and its repeat
index, so the same spec always gives the same ids and a resumed run finds its trials again.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd
from scipy.stats import qmc

from pianobot.physics.trajectory import Press
from pianobot.plan.envelope import check_envelope, raise_for_errors
from pianobot.spec import (
    PARAMETER_NAMES,
    PARAMETERS,
    ExperimentSpec,
    GridSweep,
    LhsSweep,
    Linspace,
    Range,
    RigSpec,
    clean_value,
    default_value,
    resolved_spec_dict,
)

TRIAL_ID_HEX = 16
_HASH_DECIMALS = 9  # parameters are hashed at 1e-9 resolution: YAML repr noise is far below it

Point = dict[str, float]
FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Trial:
    """One planned keystroke, in run order."""

    trial_id: str
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


def expand(spec: ExperimentSpec, rig: RigSpec | None = None) -> list[Trial]:
    """The trials of `spec` in run order (pure and deterministic for a given spec).

    With `rig`, the trials are also checked against the finger's safety envelope on that rig
    and an InputError is raised for the first error-severity violation (warnings pass).
    """
    points = _points(spec)
    base = hashlib.sha256(_spec_fingerprint(spec))
    keyed: list[tuple[Point, int, str]] = []
    occurrences: dict[tuple[object, ...], int] = {}
    for point in points:
        for repeat in range(spec.sweep.repeats):
            key = (*_hash_values(point), repeat)
            # Two random samples may coincide; the k-th copy keeps a distinct, stable id.
            nth = occurrences.get(key, 0)
            occurrences[key] = nth + 1
            digest = base.copy()
            digest.update(repr((*key, nth)).encode())
            keyed.append((point, repeat, digest.hexdigest()[:TRIAL_ID_HEX]))
    order = _run_order(spec, [p for p, _, _ in keyed])
    trials = [_trial(keyed[k], index) for index, k in enumerate(order)]
    if rig is not None:
        label = str(spec.source_path) if spec.source_path else spec.name
        raise_for_errors(check_envelope(trials, spec.finger, rig, rig_label=spec.rig), label)
    return trials


def plan_frame(trials: Sequence[Trial]) -> pd.DataFrame:
    """The plan as a table: one row per trial, columns as in `Trial` (plan.parquet)."""
    columns: dict[str, list[Any]] = {name: [] for name in PLAN_COLUMNS}
    for trial in trials:
        for name in PLAN_COLUMNS:
            columns[name].append(getattr(trial, name))
    frame = pd.DataFrame(columns)
    dtypes = {"trial_id": "string", "index": "int64", "repeat": "int64", "note": "int64"}
    return frame.astype({**{n: "float64" for n in PLAN_COLUMNS}, **dtypes})


def _trial(item: tuple[Point, int, str], index: int) -> Trial:
    point, repeat, trial_id = item
    values = {name: point[name] for name in PARAMETER_NAMES}
    values["note"] = int(values["note"])
    return Trial(trial_id=trial_id, index=index, repeat=repeat, **values)  # type: ignore[arg-type]


def _spec_fingerprint(spec: ExperimentSpec) -> bytes:
    """Canonical bytes of the resolved spec; the order parameters were listed in is part of it."""
    resolved = _rounded(resolved_spec_dict(spec))
    nesting = list(resolved["sweep"]["params"])
    return json.dumps([resolved, nesting], sort_keys=True, separators=(",", ":")).encode()


def _rounded(value: Any) -> Any:
    if isinstance(value, float):
        return round(value, _HASH_DECIMALS) + 0.0
    if isinstance(value, dict):
        return {k: _rounded(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_rounded(v) for v in value]
    return value


def _hash_values(point: Point) -> tuple[object, ...]:
    return tuple(
        int(point[n]) if PARAMETERS[n].integer else round(point[n], _HASH_DECIMALS) + 0.0
        for n in PARAMETER_NAMES
    )


def _points(spec: ExperimentSpec) -> list[Point]:
    """The sweep's points before ordering and repeats, with held values and defaults filled in."""
    sweep = spec.sweep
    if isinstance(sweep, GridSweep):
        names = sweep.params.names()
        levels = [
            value.values() if isinstance(value, Linspace) else [clean_value(v) for v in value]
            for _, value in sweep.params.items()
        ]
        varied = [dict(zip(names, combo, strict=True)) for combo in itertools.product(*levels)]
    else:
        varied = _samples(spec)
    held = {name: float(value) for name, value in sweep.fixed.items()}
    points = []
    for values in varied:
        point: Point = {}
        for name in PARAMETER_NAMES:
            if name in values:
                point[name] = values[name]
            elif name in held:
                point[name] = held[name]
            elif (default := default_value(name, spec)) is not None:
                point[name] = default
        # The study moved up at the speed it moved down; so does a spec that does not say.
        point.setdefault("up_velocity_mps", point["down_velocity_mps"])
        points.append(point)
    return points


def _samples(spec: ExperimentSpec) -> list[Point]:
    """Random or Latin-hypercube samples of the sampled parameters."""
    sweep = spec.sweep
    assert not isinstance(sweep, GridSweep)
    items = sweep.params.items()
    sampling_seed, _ = np.random.SeedSequence(sweep.seed).spawn(2)
    rng = np.random.default_rng(sampling_seed)
    n = sweep.samples
    if isinstance(sweep, LhsSweep) and items:
        # One stratum per sample along every axis: the hypercube's unit coordinates.
        unit = qmc.LatinHypercube(d=len(items), seed=rng).random(n)
    else:
        unit = rng.random((n, len(items)))
    columns = {name: _scale(value, unit[:, j], PARAMETERS[name].integer)
               for j, (name, value) in enumerate(items)}
    return [{name: float(col[i]) for name, col in columns.items()} for i in range(n)]


def _scale(value: Range | list[float], u: FloatArray, integer: bool) -> FloatArray:
    """Map unit samples onto a range (uniform) or onto a list of choices (equal weights)."""
    if isinstance(value, Range):
        if integer:
            low, high = math.ceil(value.low), math.floor(value.high)
            notes: FloatArray = np.minimum(low + np.floor(u * (high - low + 1)), high)
            return notes
        return np.array([clean_value(v) for v in value.low + u * (value.high - value.low)])
    choices = np.array([clean_value(v) for v in value], dtype=np.float64)
    picked: FloatArray = choices[np.minimum((u * len(choices)).astype(int), len(choices) - 1)]
    return picked


def _run_order(spec: ExperimentSpec, points: list[Point]) -> list[int]:
    """Positions into the point-major list (repeats back to back), in run order."""
    sweep = spec.sweep
    n = len(points)
    _, order_seed = np.random.SeedSequence(sweep.seed).spawn(2)
    rng = np.random.default_rng(order_seed)
    if sweep.order == "as-listed":
        return list(range(n))
    if sweep.order == "shuffled":
        return [int(i) for i in rng.permutation(n)]
    # blocked-shuffle: slow settings (vacuum takes seconds to settle) stay together; the blocks
    # run in the order they first appear, the trials inside each block in a random order.
    blocks: dict[tuple[float, ...], list[int]] = {}
    for i, point in enumerate(points):
        blocks.setdefault(tuple(point[name] for name in sweep.block_by), []).append(i)
    return [members[int(j)] for members in blocks.values() for j in rng.permutation(len(members))]


