"""Expand a spec into the exact list of trials that will run: pure, deterministic, persisted first.

`expand(spec)` turns a grid, random or Latin-hypercube sweep into `Trial`s in run order, each
with a stable `trial_id`: a hash of the resolved spec, the trial's parameters and its repeat
index, so the same spec always gives the same ids and a resumed run finds its trials again.
The work is done on parameter columns a chunk at a time, so a 100,000-trial plan takes about
a second and memory grows with the trials, never with a meshgrid of every level.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import fields
from typing import Any

import numpy as np
import numpy.typing as npt

from pianobot.errors import InputError
from pianobot.plan.envelope import check_envelope, raise_for_errors
from pianobot.plan.size import DEFAULT_MAX_TRIALS, check_size
from pianobot.plan.trial import FloatArray, SequenceTrial, Trial
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
from pianobot.spec.parameters import missing_value
from pianobot.spec.sweep import VALUE_DECIMALS, SequenceSweep

TRIAL_ID_HEX = 16
_HASH_DECIMALS = 9  # parameters are hashed at 1e-9 resolution: YAML repr noise is far below it
_CHUNK = 65_536  # trials built at a time

Columns = dict[str, FloatArray]
IntArray = npt.NDArray[np.int64]


def expand(
    spec: ExperimentSpec, rig: RigSpec | None = None, *, max_trials: int = DEFAULT_MAX_TRIALS
) -> list[Trial]:
    """The trials of `spec` in run order (pure and deterministic for a given spec).

    Each point of the sweep is pressed `repeats` times back to back, then `order` rearranges
    the trials. The size is checked first (`check_size`: more than `max_trials` is an
    InputError naming the count and its lab time), and the trials are then built a chunk at a
    time from their grid indices, so nothing the size of "every level of every parameter" is
    ever allocated. With `rig`, the trials are also checked against the finger's safety
    envelope on that rig and an InputError is raised for the first error-severity violation.
    """
    label = str(spec.source_path) if spec.source_path else spec.name
    check_size(spec, rig, max_trials=max_trials)
    source = _PointSource(spec, label)
    repeats = spec.sweep.repeats
    n = source.n_points * repeats
    trial_ids = _trial_ids(spec, source, repeats)
    order = _run_order(spec, source, repeats)
    trials: list[Trial] = []
    for start in range(0, n, _CHUNK):
        positions = order[start:start + _CHUNK]
        columns = source.columns(positions // repeats)
        repeat = (positions % repeats).tolist()
        # By name: each row of parameter values becomes the Trial's keyword arguments.
        rows = zip(*(columns[name].astype(np.int64).tolist() if PARAMETERS[name].integer
                     else columns[name].tolist() for name in PARAMETER_NAMES), strict=True)
        trials += [
            Trial(trial_id, index, k, **dict(zip(PARAMETER_NAMES, row, strict=True)))
            for trial_id, index, k, row in zip(
                [trial_ids[k] for k in positions.tolist()],
                range(start, start + len(positions)), repeat, rows, strict=True)
        ]
    if isinstance(spec.sweep, SequenceSweep):
        trials = _in_sequences(trials, spec.sweep.length)
    if rig is not None:
        raise_for_errors(check_envelope(trials, spec.finger, rig, rig_label=spec.rig), label)
    return trials


def _in_sequences(trials: list[Trial], length: int) -> list[Trial]:
    """A sequence sweep's trials (drawn and played in order): consecutive runs of `length`."""
    names = [f.name for f in fields(Trial)]
    return [SequenceTrial(**{name: getattr(t, name) for name in names}, sequence_id=t.index // length,
                          sequence_order=t.index % length) for t in trials]


class _PointSource:
    """Every parameter of any point of the sweep, by point index (before repeats and order).

    A grid point's levels come from its index (`unravel_index`, first parameter outermost);
    sampled points are drawn once (the sampler needs them all) and indexed.
    """

    def __init__(self, spec: ExperimentSpec, label: str) -> None:
        sweep = spec.sweep
        self.varied: dict[str, FloatArray] = {}
        if isinstance(sweep, GridSweep):
            self.levels = {
                name: np.array(value.values() if isinstance(value, Linspace) else
                               [clean_value(v) for v in value], dtype=np.float64)
                for name, value in sweep.params.items()
            }
            self.shape = tuple(len(v) for v in self.levels.values())
            self.n_points = math.prod(self.shape)
        else:
            self.levels = {}
            self.shape = ()
            self.varied = _samples(spec)
            self.n_points = sweep.samples
        self.held: dict[str, float] = {name: float(value) for name, value in sweep.fixed.items()}
        for name in PARAMETER_NAMES:
            if name in self.levels or name in self.varied or name in self.held:
                continue
            default = default_value(name, spec)
            if default is not None:
                self.held[name] = default
            elif PARAMETERS[name].follows is None:
                raise InputError(f"{name} is not set: give it in sweep.params or sweep.fixed",
                                 f"{label}: sweep.params")

    def level_indices(self, points: IntArray) -> dict[str, IntArray]:
        """Per grid parameter, the index of each point's level."""
        if not self.levels:
            return {}
        return dict(zip(self.levels, np.unravel_index(points, self.shape), strict=True))

    def columns(self, points: IntArray) -> Columns:
        """Every parameter (PARAMETER_NAMES order) of the given points."""
        n = len(points)
        columns: Columns = {}
        for name, index in self.level_indices(points).items():
            columns[name] = self.levels[name][index]
        for name, values in self.varied.items():
            columns[name] = values[points].astype(np.float64)
        for name, value in self.held.items():
            columns[name] = np.full(n, value)
        for name in PARAMETER_NAMES:  # what is left follows another parameter (up ← down)
            if name not in columns:
                followed = missing_value(name, columns)
                assert followed is not None  # a parameter without default follows one, or raised
                columns[name] = np.array(followed, dtype=np.float64)
        return {name: columns[name] for name in PARAMETER_NAMES}


def _samples(spec: ExperimentSpec) -> Columns:
    """Random or Latin-hypercube samples of the sampled parameters."""
    sweep = spec.sweep
    assert not isinstance(sweep, GridSweep)
    items = sweep.params.items()
    sampling_seed, _ = np.random.SeedSequence(sweep.seed).spawn(2)
    rng = np.random.default_rng(sampling_seed)
    n = sweep.samples
    if isinstance(sweep, LhsSweep) and items:
        # scipy.stats takes a second to import: only Latin-hypercube plans pay for it.
        from scipy.stats import qmc

        # One stratum per sample along every axis: the hypercube's unit coordinates.
        unit = qmc.LatinHypercube(d=len(items), seed=rng).random(n)
    else:
        unit = rng.random((n, len(items)))
    return {name: _scale(value, unit[:, j], PARAMETERS[name].integer)
            for j, (name, value) in enumerate(items)}


def _scale(value: Range | list[float], u: FloatArray, integer: bool) -> FloatArray:
    """Map unit samples onto a range (uniform) or onto a list of choices (equal weights)."""
    if isinstance(value, Range):
        if integer:  # whole numbers from ceil(low) to floor(high), each equally likely
            low, high = math.ceil(value.low), math.floor(value.high)
            notes: FloatArray = np.minimum(low + np.floor(u * (high - low + 1)), high)
            return notes
        scaled: FloatArray = np.round(value.low + u * (value.high - value.low), VALUE_DECIMALS)
        return scaled + 0.0
    choices = np.array([clean_value(v) for v in value], dtype=np.float64)
    picked: FloatArray = choices[np.minimum((u * len(choices)).astype(np.int64), len(choices) - 1)]
    return picked


def _trial_ids(spec: ExperimentSpec, source: _PointSource, repeats: int) -> list[str]:
    """16 hex of sha256(resolved spec, rounded parameters, repeat, occurrence) per trial, in
    point-major order (each point's repeats back to back)."""
    base = hashlib.sha256(_spec_fingerprint(spec))
    ids: list[str] = []
    seen: dict[bytes, int] = {}
    n = source.n_points * repeats
    for start in range(0, n, _CHUNK):
        positions = np.arange(start, min(n, start + _CHUNK), dtype=np.int64)
        columns = source.columns(positions // repeats)
        # One little-endian float64 row per trial: the same rounded values give the same bytes
        # on every machine (adding 0.0 turns -0.0 into 0.0).
        table = np.column_stack(
            [np.round(columns[name], _HASH_DECIMALS) + 0.0 for name in PARAMETER_NAMES]
            + [positions % repeats]
        ).astype("<f8")
        width = table.shape[1] * 8
        data = np.ascontiguousarray(table).tobytes()
        for row in range(0, len(data), width):
            key = data[row : row + width]
            # Two random samples may coincide; the k-th copy keeps a distinct, stable id.
            nth = seen.get(key, 0)
            seen[key] = nth + 1
            digest = base.copy()
            digest.update(key + nth.to_bytes(4, "little"))
            ids.append(digest.hexdigest()[:TRIAL_ID_HEX])
    return ids


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


def _run_order(spec: ExperimentSpec, source: _PointSource, repeats: int) -> IntArray:
    """Positions into the point-major list (repeats back to back), in run order."""
    sweep = spec.sweep
    n = source.n_points * repeats
    _, order_seed = np.random.SeedSequence(sweep.seed).spawn(2)
    rng = np.random.default_rng(order_seed)
    if sweep.order == "as-listed":
        return np.arange(n, dtype=np.int64)
    if sweep.order == "shuffled":
        return rng.permutation(n).astype(np.int64)
    # blocked-shuffle: slow settings (vacuum takes seconds to settle) stay together; the blocks
    # run in the order the spec lists their levels, the trials inside each block shuffled.
    # Each trial's block is a code (one per distinct combination of the blocking values, in
    # order of first appearance), computed chunk by chunk.
    codes = np.empty(n, dtype=np.int64)
    blocks: dict[tuple[float, ...], int] = {}
    for start in range(0, n, _CHUNK):
        positions = np.arange(start, min(n, start + _CHUNK), dtype=np.int64)
        columns = source.columns(positions // repeats)
        keys = (zip(*(columns[name].tolist() for name in sweep.block_by), strict=True)
                if sweep.block_by else [()] * len(positions))  # no slow parameter: one block
        codes[start:start + len(positions)] = [blocks.setdefault(key, len(blocks)) for key in keys]
    ranks = [_level_rank(spec, name, [key[j] for key in blocks]) for j, name in
             enumerate(sweep.block_by)]
    ordered = sorted(blocks, key=lambda key: tuple(rank[v] for rank, v in zip(ranks, key, strict=True)))
    # Members of each block in point-major order (a stable sort by code keeps it).
    by_code = np.argsort(codes, kind="stable")
    bounds = np.searchsorted(codes[by_code], np.arange(len(blocks) + 1))
    parts = []
    for key in ordered:
        code = blocks[key]
        members = by_code[bounds[code]:bounds[code + 1]]
        parts.append(members[rng.permutation(len(members))])
    return np.concatenate(parts) if parts else np.arange(0, dtype=np.int64)


def _level_rank(spec: ExperimentSpec, name: str, seen: list[float]) -> dict[float, int]:
    """Rank of each value of a blocking parameter: its place in the spec's list of levels or
    choices, else (a sampled range, a held value) the order it first appears in."""
    value = dict(spec.sweep.params.items()).get(name)
    if isinstance(value, Linspace):
        listed = value.values()
    elif isinstance(value, list):
        listed = [clean_value(v) for v in value]
    else:
        listed = []
    rank = {v: i for i, v in reversed(list(enumerate(listed)))}
    for v in seen:
        rank.setdefault(v, len(rank))
    return rank
