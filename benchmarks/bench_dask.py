"""Dask benchmark: one simulated sweep serially, on a local cluster of 1 process and of 2.

    python benchmarks/bench_dask.py                 # 675 grid trials, best of 2, ~1-3 min idle
    python benchmarks/bench_dask.py --speeds 15     # the whole 2,025-trial study grid
    python benchmarks/bench_dask.py --quick         # 135 trials, to check the script

The sweep is the study grid (experiments/soft_finger_grid.yaml) cut to `--speeds` down speeds,
every stream stored, in three ways, interleaved `--repeat` times (best wall time of each kept):

- `serial`: one worker in this process (`--workers 1`, the default for small sweeps);
- `cluster_1`: the driver here and a LocalCluster of 1 worker process;
- `cluster_2`: the driver here and a LocalCluster of 2 worker processes (`--workers 2`).

The figures that answer "does a second process help": `speedup_2_vs_1_process` (the same code
path, one more worker) and `speedup_2_vs_serial` (what a user gains over the default). Both need
cores to spare: `load_average` (start, end) and `usable_cores` are recorded, and the CPU split
says where the work goes (`driver_cpu_s`: this process, which keeps the run's timeline, journal,
writes and the final compaction; `workers_cpu_s`: the simulation, observation and encoding).
From that split, `bound_on_c_cores` is the speed-up the measured work allows on c idle cores
(the driver's part runs once, the workers' part splits). Data are checked identical to serial.

JSON goes to stdout and benchmarks/results/dask.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_sweep import _grid_spec  # noqa: E402  (the study grid with fewer speeds)

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results"


def _workers_cpu_s(client: Any) -> float:
    """CPU seconds the cluster's worker processes have used so far."""
    return float(sum(client.run(time.process_time).values()))


def _cluster(workers: int) -> Any:
    from pianobot.executor import Executor, _local_client

    return Executor("local-cluster", workers, _local_client(workers))


def _run(spec: Path, data: Path, executor: Any | None, block: int) -> dict[str, Any]:
    """One sweep; `executor` None: serial in this process."""
    import pianobot.run.sweep as sweep
    from pianobot.executor import ExecutorSettings

    original = sweep.open_executor
    if executor is not None:
        sweep.open_executor = lambda *a, **k: executor  # type: ignore[assignment]
    client = getattr(executor, "_client", None)
    try:
        before = _workers_cpu_s(client) if client is not None else 0.0
        wall, cpu = time.perf_counter(), time.process_time()
        outcome = sweep.run_sweep(spec, data_dir=data, progress=False, batch_trials=block,
                                  executor=ExecutorSettings(workers=1 if executor is None else 2))
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        workers = (_workers_cpu_s(client) - before) if client is not None else 0.0
    finally:
        sweep.open_executor = original  # type: ignore[assignment]
    return {"run_id": outcome.run_id, "trials": outcome.trials, "status": outcome.status,
            "wall_s": wall, "driver_cpu_s": cpu, "workers_cpu_s": workers,
            "executor": "serial" if executor is None else f"local-cluster of {executor.workers}"}


def machine(load_start: tuple[float, float, float]) -> dict[str, Any]:
    """What the figures were measured on: Python, cores, and the load before and after."""
    from pianobot.executor import usable_cores

    return {"python": platform.python_version(), "cpus": os.cpu_count(), "usable_cores": usable_cores(),
            "platform": platform.platform(), "load_average_start": load_start, "load_average_end": os.getloadavg()}


def emit(result: dict[str, Any], name: str, quick: bool) -> None:
    """Print the result as JSON and, unless a quick check, keep it in benchmarks/results/NAME."""
    text = json.dumps(result, indent=2)
    print(text)
    if not quick:
        RESULTS.mkdir(parents=True, exist_ok=True)
        (RESULTS / name).write_text(text + "\n")


def _same_data(data_a: Path, run_a: str, data_b: Path, run_b: str) -> bool:
    from pianobot.store import load_run

    a, b = load_run(run_a, data_a), load_run(run_b, data_b)
    for name in ("trials", "samples", "midi"):
        x = a.table(name).drop(columns=["run_id"]).reset_index(drop=True)
        y = b.table(name).drop(columns=["run_id"]).reset_index(drop=True)
        if not x.equals(y):
            return False
    return True


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speeds", type=int, default=5, help="down speeds of the grid (15: all)")
    parser.add_argument("--repeat", type=int, default=2, help="interleaved repetitions (best kept)")
    parser.add_argument("--block", type=int, default=None,
                        help="trials per block (= per Dask task); default: the sweep's own")
    parser.add_argument("--quick", action="store_true", help="135 trials, once")
    args = parser.parse_args()
    speeds, repeat = (1, 1) if args.quick else (args.speeds, max(1, args.repeat))
    from pianobot.run.runner import BLOCK_TRIALS

    block = args.block or BLOCK_TRIALS
    load_start = os.getloadavg()
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="pianobot-bench-dask-") as tmp:
        root = Path(tmp)
        spec = _grid_spec(root / "spec", speeds)
        warm_spec = _grid_spec(root / "warm", 1)
        configs: dict[str, Any] = {"serial": None}
        start_s: dict[str, float] = {}
        for workers in (1, 2):
            t0 = time.perf_counter()
            configs[f"cluster_{workers}"] = _cluster(workers)
            start_s[f"cluster_{workers}"] = round(time.perf_counter() - t0, 2)
        for name, executor in configs.items():  # imports, compiled kernels, worlds: not timed
            _run(warm_spec, root / f"warm-{name}", executor, block)
        runs: dict[str, list[dict[str, Any]]] = {name: [] for name in configs}
        for rep in range(repeat):
            order = list(configs) if rep % 2 == 0 else list(reversed(configs))
            for name in order:
                runs[name].append(_run(spec, root / f"{name}-{rep}", configs[name], block))
        best = {name: min(results, key=lambda r: r["wall_s"]) for name, results in runs.items()}
        identical = _same_data(root / "serial-0", runs["serial"][0]["run_id"],
                               root / "cluster_2-0", runs["cluster_2"][0]["run_id"])
    trials = best["serial"]["trials"]
    two = best["cluster_2"]
    serial_cpu = best["serial"]["driver_cpu_s"]
    parallel_cpu = two["driver_cpu_s"] + two["workers_cpu_s"]

    def bound(cores: int) -> float:
        # The driver's work runs once beside the workers; the workers' work splits over the
        # cores left (at least one), never over more than the 2 workers measured.
        workers_cores = max(1.0, min(2.0, cores - two["driver_cpu_s"] / max(two["wall_s"], 1e-9)))
        return round(serial_cpu / max(two["driver_cpu_s"], parallel_cpu / cores,
                                      two["workers_cpu_s"] / workers_cores), 2)

    result = {
        "benchmark": "dask", "quick": args.quick, "trials": trials, "block_trials": block,
        "repeat": repeat,
        "machine": machine(load_start),
        "cluster_start_s": start_s,
        "wall_s": {name: round(r["wall_s"], 2) for name, r in best.items()},
        "all_wall_s": {name: [round(r["wall_s"], 2) for r in rs] for name, rs in runs.items()},
        "trials_per_s_wall": {name: round(trials / r["wall_s"], 1) for name, r in best.items()},
        "speedup_2_vs_1_process": round(best["cluster_1"]["wall_s"] / two["wall_s"], 2),
        "speedup_2_vs_serial": round(best["serial"]["wall_s"] / two["wall_s"], 2),
        "cpu_s": {name: {"driver": round(r["driver_cpu_s"], 2), "workers": round(r["workers_cpu_s"], 2)}
                  for name, r in best.items()},
        "parallel_cpu_overhead": round(parallel_cpu / serial_cpu - 1.0, 3),
        "driver_share_of_serial_cpu": round(two["driver_cpu_s"] / serial_cpu, 3),
        "bound_on_c_cores": {c: bound(c) for c in (2, 3, 4)},
        "identical_to_serial": identical,
        "took_s": round(time.perf_counter() - started, 1),
    }
    emit(result, "dask.json", args.quick)


if __name__ == "__main__":
    main()
