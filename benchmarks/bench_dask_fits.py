"""Dask benchmark of the fits that split: identify's bootstrap refits, discovery's candidates and
`fit`'s cross-validation folds.

    python benchmarks/bench_dask_fits.py            # both, best of 2, ~3-6 min on 2 idle cores
    python benchmarks/bench_dask_fits.py --quick    # small sizes, to check the script

The keystrokes are an independent truth-lab take (tests/truth: a simulator sharing no code with
pianobot, written as Motive CSV and imported as a lab imports it); the CV folds learn the study's
2,025-keystroke soft grid swept on the simulated rig (`pianobot fit RUN --model gp --model poly`). Each workload runs in three
ways, interleaved `--repeat` times (best wall time kept), like `bench_dask.py` does for sweeps:

- `serial`: every piece in this process (`serial_map`, what one worker does);
- `cluster_1`: the pieces on a LocalCluster of 1 worker process (`Executor.imap`);
- `cluster_2`: the same on a LocalCluster of 2 worker processes.

`speedup_2_vs_1_process` answers "does a second process help" for the same code path. The
part that splits (the maps: refits, candidate fits) is also timed on its own (`split_*`): what
stays in the driver (the base fit, the measured checks, choosing) bounds the whole's speed-up on
any number of workers (Amdahl), and the two figures say how much. The results are checked equal to the serial ones (bootstrap intervals; discovery's decisions and
fitted values), since a piece's result may depend only on its arguments.

JSON goes to stdout and benchmarks/results/dask_fits.json.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_dask import _cluster, _workers_cpu_s, emit, machine  # noqa: E402

#: A clean take for the bootstrap (identify's refits) and a let-off take for discovery (two
#: iterations of candidates).
BOOTSTRAP_TAKE = "mocap-clean-light-finger-deep-1"
DISCOVERY_TAKE = "mocap-letoff-gaussian-strong"


def _batch(name: str, folder: Path) -> Any:
    from bench_discover import truth_batch

    from tests.truth import materialise, scenario

    made = materialise(scenario(name), folder / "files")
    batch, _ = truth_batch(made, folder / "data")
    return batch


def _bootstrap(batch: Any, replicates: int) -> Callable[[Any], Any]:
    from pianobot.analysis.identify.fit import identify_trajectories
    from pianobot.physics.msd import MSDParams

    def run(mapper: Any) -> Any:
        fit = identify_trajectories(batch, prior=MSDParams(), bootstrap=replicates, seed=3, mapper=mapper)
        return json.dumps({e.name: (e.value, e.ci_bootstrap) for e in fit.estimates}, sort_keys=True)

    return run


def _candidates(batch: Any) -> Callable[[Any], Any]:
    from pianobot.analysis.discover.loop import discover

    def run(mapper: Any) -> Any:
        result = discover(batch, mapper=mapper)
        return json.dumps([result.accepted_effects, result.final_model.effects.to_dict(), result.verdict],
                          sort_keys=True)

    return run


def _cv_trials(folder: Path) -> Any:
    from pianobot.executor import ExecutorSettings
    from pianobot.run import run_sweep
    from pianobot.store import load_run

    outcome = run_sweep(ROOT / "experiments" / "soft_finger_grid.yaml", data_dir=folder, progress=False,
                        rig_path=ROOT / "experiments" / "rigs" / "sim-extended.yaml",
                        executor=ExecutorSettings(workers=1))
    return load_run(outcome.run_id, folder).trials


def _cv_folds(trials: Any) -> Callable[[Any], Any]:
    from contextlib import nullcontext

    from pianobot.analysis.learn.training import cross_validate_models, training_set

    data = training_set(trials)

    class _Adapter:  # the executor interface cross-validation asks for, over a bare mapper
        def __init__(self, mapper: Any) -> None:
            self.imap = mapper

    def run(mapper: Any) -> Any:
        table, _ = cross_validate_models(data, ["gp", "poly"], folds=5,
                                         executor=lambda work_s: nullcontext(_Adapter(mapper)))
        return table.drop(columns=["latency_ms", "fit_s"]).to_json()

    return run


class _Timed:
    """A mapper that adds up the wall time spent inside its maps (the part of the work that splits)."""

    def __init__(self, mapper: Any) -> None:
        self.mapper = mapper
        self.wall_s = 0.0

    def __call__(self, fn: Callable[[Any], Any], items: Any) -> Iterator[Any]:
        start = time.perf_counter()
        try:
            yield from self.mapper(fn, items)
        finally:
            self.wall_s += time.perf_counter() - start


def _time(work: Callable[[Any], Any], executor: Any | None) -> dict[str, Any]:
    from pianobot.analysis.greybox.pieces import serial_map

    client = getattr(executor, "_client", None)
    before = _workers_cpu_s(client) if client is not None else 0.0
    timed = _Timed(serial_map if executor is None else executor.imap)
    wall, cpu = time.perf_counter(), time.process_time()
    value = work(timed)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    workers = (_workers_cpu_s(client) - before) if client is not None else 0.0
    return {"wall_s": wall, "split_wall_s": timed.wall_s, "driver_cpu_s": cpu, "workers_cpu_s": workers,
            "value": value}


def _workload(name: str, work: Callable[[Any], Any], configs: dict[str, Any], repeat: int) -> dict[str, Any]:
    from pianobot.analysis.greybox.pieces import serial_map

    work(serial_map)  # imports and compiled kernels, here and in each worker process: not timed
    for executor in (configs["cluster_1"], configs["cluster_2"]):
        work(executor.imap)
    runs: dict[str, list[dict[str, Any]]] = {c: [] for c in configs}
    for rep in range(repeat):
        for c in (list(configs) if rep % 2 == 0 else list(reversed(configs))):
            runs[c].append(_time(work, configs[c]))
    best = {c: min(rs, key=lambda r: r["wall_s"]) for c, rs in runs.items()}
    same = all(r["value"] == best["serial"]["value"] for rs in runs.values() for r in rs)
    two, one = best["cluster_2"], best["cluster_1"]
    return {
        "workload": name,
        "wall_s": {c: round(r["wall_s"], 2) for c, r in best.items()},
        "all_wall_s": {c: [round(r["wall_s"], 2) for r in rs] for c, rs in runs.items()},
        "cpu_s": {c: {"driver": round(r["driver_cpu_s"], 2), "workers": round(r["workers_cpu_s"], 2)}
                  for c, r in best.items()},
        "speedup_2_vs_1_process": round(one["wall_s"] / two["wall_s"], 2),
        "speedup_2_vs_serial": round(best["serial"]["wall_s"] / two["wall_s"], 2),
        "split_wall_s": {c: round(r["split_wall_s"], 2) for c, r in best.items()},
        "split_share_of_serial": round(best["serial"]["split_wall_s"] / best["serial"]["wall_s"], 2),
        "split_speedup_2_vs_1_process": round(one["split_wall_s"] / two["split_wall_s"], 2),
        "split_speedup_2_vs_serial": round(best["serial"]["split_wall_s"] / two["split_wall_s"], 2),
        "identical_to_serial": same,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=2, help="interleaved repetitions (best kept)")
    parser.add_argument("--replicates", type=int, default=32, help="bootstrap refits")
    parser.add_argument("--only", choices=("bootstrap", "candidates", "cv_folds"), default=None)
    parser.add_argument("--quick", action="store_true", help="8 refits, once")
    args = parser.parse_args()
    repeat, replicates = (1, 8) if args.quick else (max(1, args.repeat), args.replicates)

    load_start = os.getloadavg()
    started = time.perf_counter()
    os.environ.setdefault("OMP_NUM_THREADS", "1")  # as the cluster's workers run
    configs: dict[str, Any] = {"serial": None, "cluster_1": _cluster(1), "cluster_2": _cluster(2)}
    workloads = []
    with tempfile.TemporaryDirectory(prefix="pianobot-bench-dask-fits-") as tmp:
        root = Path(tmp)
        if args.only in (None, "bootstrap"):
            work = _bootstrap(_batch(BOOTSTRAP_TAKE, root / "boot"), replicates)
            workloads.append({**_workload("bootstrap", work, configs, repeat), "take": BOOTSTRAP_TAKE,
                              "replicates": replicates})
        if args.only in (None, "candidates"):
            work = _candidates(_batch(DISCOVERY_TAKE, root / "disc"))
            workloads.append({**_workload("candidates", work, configs, repeat), "take": DISCOVERY_TAKE})
        if args.only in (None, "cv_folds"):
            trials = _cv_trials(root / "cv")
            work = _cv_folds(trials)
            workloads.append({**_workload("cv_folds", work, configs, repeat), "trials": len(trials),
                              "models": ["gp", "poly"], "folds": 5})
    result = {
        "benchmark": "dask_fits", "quick": args.quick, "repeat": repeat,
        "machine": machine(load_start),
        "workloads": workloads,
        "took_s": round(time.perf_counter() - started, 1),
    }
    emit(result, "dask_fits.json", args.quick)


if __name__ == "__main__":
    main()
