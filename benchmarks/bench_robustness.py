"""Benchmark what robustness costs and what it bounds, as ratios against baselines run here.

- **store records**: `RunWriter.append` (parts + their SHA-256 and a journalled copy of the
  trials part) against writing the same three parts the way the store did before (atomic
  Parquet writes, no record); the deep integrity check of a finished 2,025-trial-sized run
  against compacting it.
- **plan expansion**: `expand()` (chunked, never a meshgrid of every level) against the
  meshgrid-of-everything it replaced, time and peak traced memory, at 10⁵ and 10⁶ trials;
  and how long refusing a 10⁹-trial spec takes.
- **YAML**: loading the study's spec, and refusing alias bombs of 6 to 9 levels (the old
  loader took 17.5 s and 832 MB at 8 levels and hung at 9).
- **lock**: acquire + release of `RunLock` against a bare O_EXCL create + unlink.

    .venv/bin/python benchmarks/bench_robustness.py [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import tempfile
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pianobot.errors import InputError
from pianobot.plan import expand
from pianobot.spec import ExperimentSpec, load_spec
from pianobot.store import RunLock, RunWriter, check_run
from pianobot.store.layout import RunPaths, write_parquet_atomic
from pianobot.store.schema import to_table, with_metadata

RESULTS = Path(__file__).resolve().parent / "results" / "robustness.json"
REPO = Path(__file__).resolve().parents[1]


def _median_s(fn: Callable[[], object], repeats: int = 5) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def _batch(n_trials: int, samples_per_trial: int, seed: int) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    rng = np.random.default_rng(seed)
    ids = [f"{seed:04d}{i:012d}" for i in range(n_trials)]
    trials = pd.DataFrame({"trial_id": ids, "index": range(n_trials), "attempt": 1, "status": "ok",
                           "note": 57, "vacuum_kpa": -40.0, "down_velocity_mps": rng.uniform(0.01, 0.06, n_trials),
                           "on_velocity": rng.uniform(1, 60, n_trials), "n_note_on": 1})
    t = np.tile(np.arange(samples_per_trial) * 0.002, n_trials)
    samples = pd.DataFrame({"trial_id": np.repeat(ids, samples_per_trial), "source": "arm", "t_s": t,
                            "x0_m": rng.normal(0, 1e-3, t.size), "x1_m": rng.normal(0, 1e-3, t.size),
                            "x2_m": rng.normal(0, 1e-3, t.size)})
    midi = pd.DataFrame({"trial_id": ids, "t_s": rng.uniform(0, 1, n_trials), "type": "note_on",
                         "note": 57, "velocity": 64})
    return trials, samples, midi


def bench_store(work: Path) -> dict[str, Any]:
    """Append with records vs the old plain atomic writes; deep check vs compaction."""
    batches = [_batch(50, 1500, seed) for seed in range(41)]  # ~2,050 trials, 1,500 arm samples each
    writer = RunWriter.create(work / "data", name="bench", kind="import", meta={}, plan=None)
    plain = work / "plain"
    plain.mkdir()

    def new_append() -> None:
        for trials, samples, midi in batches[:10]:
            writer.append(trials, samples, midi)

    def old_append() -> None:  # what append did before: three atomic Parquet writes, no record
        for k, (trials, samples, midi) in enumerate(batches[:10]):
            for name, frame in (("samples", samples), ("midi", midi), ("trials", trials)):
                write_parquet_atomic(plain / f"{name}-{k:06d}.parquet",
                                     with_metadata(to_table(frame, name, "bench"), name))

    old_s = _median_s(old_append, 3)
    new_s = _median_s(new_append, 3)
    for trials, samples, midi in batches[10:]:
        writer.append(trials, samples, midi)
    paths = RunPaths(writer.path)
    check_parts_s = _median_s(lambda: check_run(paths, deep=True), 3)
    quick_parts_s = _median_s(lambda: check_run(paths, deep=False), 3)
    start = time.perf_counter()
    writer.finish("completed")  # includes its own deep check first
    finish_s = time.perf_counter() - start
    writer.close()
    check_compacted_s = _median_s(lambda: check_run(paths, deep=True), 3)
    journal_bytes = paths.journal.stat().st_size
    data_bytes = sum(p.stat().st_size for p in paths.root.glob("*.parquet"))
    return {
        "append_10_batches_with_records_s": new_s,
        "append_10_batches_plain_s": old_s,
        "append_ratio": new_s / old_s,
        "deep_check_of_parts_s": check_parts_s,
        "quick_check_of_parts_s": quick_parts_s,
        "finish_with_verify_and_compaction_s": finish_s,
        "deep_check_share_of_finish": check_parts_s / finish_s,
        "deep_check_of_compacted_run_s": check_compacted_s,
        "journal_bytes": journal_bytes,
        "data_bytes": data_bytes,
        "journal_to_data_bytes": journal_bytes / data_bytes,
        "trials": sum(len(b[0]) for b in batches),
    }


def _grid_spec(levels: int, n_params: int = 4) -> ExperimentSpec:
    names = ["vacuum_kpa", "down_velocity_mps", "acceleration_mps2", "depth_m"][:n_params]
    ranges = {"vacuum_kpa": (-80.0, 0.0), "down_velocity_mps": (0.01, 0.06),
              "acceleration_mps2": (0.1, 2.0), "depth_m": (0.02, 0.035)}
    params = {n: {"start": ranges[n][0], "stop": ranges[n][1], "num": levels} for n in names}
    return ExperimentSpec.model_validate({"name": "bench", "finger": "soft",
                                          "sweep": {"mode": "grid", "params": params}})


def _meshgrid_everything(spec: ExperimentSpec) -> int:
    """The expansion it replaced: one meshgrid of all levels, raveled into full columns."""
    levels = [np.array(v.values()) for _, v in spec.sweep.params.items()]  # type: ignore[union-attr]
    grids = np.meshgrid(*levels, indexing="ij")
    columns = [g.ravel() for g in grids]
    return len(columns[0])


def _traced(fn: Callable[[], object]) -> tuple[float, float]:
    tracemalloc.start()
    start = time.perf_counter()
    fn()
    seconds = time.perf_counter() - start
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return seconds, peak / 2**20


def bench_plan() -> dict[str, Any]:
    out: dict[str, Any] = {}
    for levels in (18, 32):  # 104,976 and 1,048,576 trials
        spec = _grid_spec(levels)
        n = levels**4
        row: dict[str, float] = {"expand_s": _median_s(lambda spec=spec, n=n: expand(spec, max_trials=n), 1),
                                 "meshgrid_intermediate_mib": n * 4 * 8 * 2 / 2**20}
        if n < 200_000:  # tracemalloc slows object creation ~25x: the peak is measured once, small
            _, row["expand_peak_mib"] = _traced(lambda spec=spec, n=n: expand(spec, max_trials=n))
            _, row["meshgrid_everything_peak_mib"] = _traced(lambda spec=spec: _meshgrid_everything(spec))
            row["expand_peak_per_trial_bytes"] = row["expand_peak_mib"] * 2**20 / n
        out[f"{n}_trials"] = row
    huge = _grid_spec(178)
    start = time.perf_counter()
    try:
        expand(huge)
    except InputError as exc:
        out["refuse_1e9_trials_s"] = time.perf_counter() - start
        out["refuse_1e9_message"] = str(exc)
    return out


def bench_yaml(work: Path) -> dict[str, Any]:
    out: dict[str, Any] = {}
    study = REPO / "experiments" / "soft_finger_grid.yaml"
    rig = REPO / "experiments" / "rigs" / "sim-extended.yaml"
    out["load_study_spec_s"] = _median_s(lambda: load_spec(study, rig=rig), 5)
    for levels in (6, 7, 8, 9):
        lines = ["name: bomb", "finger: soft", "x0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"]
        lines += [f"x{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 10) + "]" for i in range(1, levels + 1)]
        lines.append("sweep: {mode: grid, params: {down_velocity_mps: [0.02], depth_m: [0.03]}}")
        path = work / f"bomb{levels}.yaml"
        path.write_text("\n".join(lines) + "\n")

        def refuse(path: Path = path) -> None:
            try:
                load_spec(path)
            except InputError:
                return
            raise AssertionError("an alias bomb was accepted")

        seconds, peak = _traced(refuse)
        out[f"refuse_bomb_{levels}_levels"] = {"s": seconds, "peak_mib": peak}
    return out


def bench_lock(work: Path) -> dict[str, Any]:
    path = work / "run.lock"

    def run_lock() -> None:
        for _ in range(100):
            RunLock(path).acquire().release()

    def bare() -> None:
        for _ in range(100):
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL)
            os.write(fd, b"1\n")
            os.close(fd)
            path.unlink()

    lock_s, bare_s = _median_s(run_lock, 3) / 100, _median_s(bare, 3) / 100
    return {"run_lock_acquire_release_s": lock_s, "bare_exclusive_create_s": bare_s,
            "ratio": lock_s / bare_s}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="bench-robustness-"))
    try:
        results = {"store": bench_store(work), "plan": bench_plan(), "yaml": bench_yaml(work),
                   "lock": bench_lock(work), "load_average": os.getloadavg()}
    finally:
        shutil.rmtree(work, ignore_errors=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2) + "\n")
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
