"""Expand a spec into the exact list of trials that will run: pure, deterministic, persisted first.

`expand(spec)` turns a grid, random or Latin-hypercube sweep into `Trial`s in run order, each
with a stable `trial_id`: a hash of the resolved spec, the trial's parameters and its repeat
index, so the same spec always gives the same ids and a resumed run finds its trials again.
The work is done on parameter columns, so a 100,000-trial plan takes about a second.
"""

from __future__ import annotations

import hashlib
import json
import math
from typing import Any

import numpy as np

from pianobot.errors import InputError
from pianobot.plan.envelope import check_envelope, raise_for_errors
from pianobot.plan.trial import FloatArray, Trial
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
from pianobot.spec.sweep import VALUE_DECIMALS

TRIAL_ID_HEX = 16
_HASH_DECIMALS = 9  # parameters are hashed at 1e-9 resolution: YAML repr noise is far below it

Columns = dict[str, FloatArray]


def expand(spec: ExperimentSpec, rig: RigSpec | None = None) -> list[Trial]:
    """The trials of `spec` in run order (pure and deterministic for a given spec).

    Each point of the sweep is pressed `repeats` times back to back, then `order` rearranges
    the trials. With `rig`, the trials are also checked against the finger's safety envelope
    on that rig and an InputError is raised for the first error-severity violation.
    """
    label = str(spec.source_path) if spec.source_path else spec.name
    points = _point_columns(spec, label)
    repeats = spec.sweep.repeats
    n_points = len(points["note"])
    columns = {name: np.repeat(values, repeats) for name, values in points.items()}
    repeat = np.tile(np.arange(repeats), n_points)
    trial_ids = _trial_ids(spec, columns, repeat)
    order = np.array(_run_order(spec, columns), dtype=np.int64)
    in_order = [columns[name][order] for name in PARAMETER_NAMES]
    # Trial's fields after (trial_id, index, repeat) are PARAMETER_NAMES, note first.
    trials = list(map(
        Trial,
        [trial_ids[k] for k in order.tolist()],
        range(len(order)),
        repeat[order].tolist(),
        in_order[0].astype(np.int64).tolist(),
        *(values.tolist() for values in in_order[1:]),
    ))
    if rig is not None:
        raise_for_errors(check_envelope(trials, spec.finger, rig, rig_label=spec.rig), label)
    return trials


def _point_columns(spec: ExperimentSpec, label: str) -> Columns:
    """Every parameter of every point of the sweep (before repeats and ordering)."""
    sweep = spec.sweep
    if isinstance(sweep, GridSweep):
        levels = [
            np.array(value.values() if isinstance(value, Linspace) else
                     [clean_value(v) for v in value], dtype=np.float64)
            for _, value in sweep.params.items()
        ]
        # 'ij' indexing nests the first listed parameter outermost, as the spec reads.
        grids = np.meshgrid(*levels, indexing="ij") if levels else []
        varied = {name: g.ravel() for name, g in zip(sweep.params.names(), grids, strict=True)}
        n = int(np.prod([len(v) for v in levels])) if levels else 1
    else:
        varied = _samples(spec)
        n = sweep.samples
    held = {name: float(value) for name, value in sweep.fixed.items()}
    columns: Columns = {}
    for name in PARAMETER_NAMES:
        if name in varied:
            columns[name] = varied[name].astype(np.float64)
        elif name in held:
            columns[name] = np.full(n, held[name])
        elif (default := default_value(name, spec)) is not None:
            columns[name] = np.full(n, default)
        elif name != "up_velocity_mps":
            raise InputError(f"{name} is not set: give it in sweep.params or sweep.fixed",
                             f"{label}: sweep.params")
    # The study moved up at the speed it moved down; so does a spec that does not say.
    columns.setdefault("up_velocity_mps", columns["down_velocity_mps"].copy())
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


def _trial_ids(spec: ExperimentSpec, columns: Columns, repeat: Any) -> list[str]:
    """16 hex of sha256(resolved spec, rounded parameters, repeat, occurrence) per trial."""
    base = hashlib.sha256(_spec_fingerprint(spec))
    # One little-endian float64 row per trial: the same rounded values give the same bytes on
    # every machine (adding 0.0 turns -0.0 into 0.0).
    table = np.column_stack(
        [np.round(columns[n], _HASH_DECIMALS) + 0.0 for n in PARAMETER_NAMES] + [repeat]
    ).astype("<f8")
    width = table.shape[1] * 8
    data = np.ascontiguousarray(table).tobytes()
    ids = []
    seen: dict[bytes, int] = {}
    for start in range(0, len(data), width):
        key = data[start : start + width]
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


def _run_order(spec: ExperimentSpec, columns: Columns) -> list[int]:
    """Positions into the point-major list (repeats back to back), in run order."""
    sweep = spec.sweep
    n = len(columns["note"])
    _, order_seed = np.random.SeedSequence(sweep.seed).spawn(2)
    rng = np.random.default_rng(order_seed)
    if sweep.order == "as-listed":
        return list(range(n))
    if sweep.order == "shuffled":
        return [int(i) for i in rng.permutation(n)]
    # blocked-shuffle: slow settings (vacuum takes seconds to settle) stay together; the blocks
    # run in the order the spec lists their levels, the trials inside each block shuffled.
    blocks: dict[tuple[float, ...], list[int]] = {}
    keys: list[tuple[float, ...]] = (
        list(zip(*(columns[name].tolist() for name in sweep.block_by), strict=True))
        if sweep.block_by else [()] * n  # no slow parameter: one block, i.e. shuffled
    )
    for i, key in enumerate(keys):
        blocks.setdefault(key, []).append(i)
    ranks = [_level_rank(spec, name, [key[j] for key in blocks]) for j, name in
             enumerate(sweep.block_by)]
    ordered = sorted(blocks, key=lambda key: tuple(rank[v] for rank, v in zip(ranks, key, strict=True)))
    return [m for key in ordered for m in (blocks[key][int(j)] for j in rng.permutation(len(blocks[key])))]


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
