"""Sweep benchmark: simulated sweeps against the physics they run, side by side in one run.

    python benchmarks/bench_sweep.py            # grid, 10,000 random, Dask 2 vs 1, lab time
    python benchmarks/bench_sweep.py --large    # also 100,000 random trials and 1,000,000 for RSS
    python benchmarks/bench_sweep.py --quick    # small sizes, to check the script itself

Every sweep stores every stream (MIDI, arm, mocap and the simulated truth). Figures:

1. `grid`: the study's 2,025-trial grid (experiments/soft_finger_grid.yaml), one worker. Its
   throughput is compared, in the same process, with (a) the raw simulator on the same 2,025
   presses (the batch integrator alone, sorted into batches of similar length: what the physics
   needs) and (b) the one-keystroke-at-a-time path the sweep used before (on 405 of the trials).
2. `random`: a random sweep (10,000 trials; 100,000 with --large) of short strokes from 10 mm
   above the key, the same comparison with the raw simulator, and RSS sampled along the run.
3. `rss_1m` (--large): 1,000,000 trials, RSS every 100,000 trials (bounded: no per-trial
   state grows). The world samples its truth at 200 Hz and the arm at 125 Hz there, to keep the
   run's data near 10 GB on disk.
4. `dask`: the grid's first 675 trials on a local Dask cluster of 2 worker processes against 1
   worker (in this process), wall time and speed-up, the data checked identical.
5. `lab_time`: the study grid's planned lab time as specified, with `approach: fast`, and by
   the study's own script (0.5 s sleep before and after each press plus the two moveLs).

Times are wall-clock and CPU (this process only; `dask` counts the workers' CPU as well). The
machine may be shared: ratios are measured in the same run, and `load_average` says how busy
it was. Each scenario runs in a fresh interpreter so its peak RSS is its own. JSON goes to
stdout and to benchmarks/results/sweep.json (and sweep_large.json with --large).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results"
GRID = REPO / "experiments" / "soft_finger_grid.yaml"
STUDY_SLEEP_S = 0.5  # the study's script: time.sleep(0.5) before and after every press

RANDOM_SPEC = """\
name: bench-random
rig: rig.yaml
finger: soft
note: 57
sweep:
  mode: random
  samples: {samples}
  seed: 1
  params:
    vacuum_kpa: [0, -20, -40, -60, -80]
    down_velocity_mps: {{low: 0.02, high: 0.06}}
    acceleration_mps2: {{low: 0.3, high: 1.0}}
    depth_m: {{low: 0.02, high: 0.035}}
  fixed: {{distance_m: {distance}, hold_s: 0.0}}
  order: blocked-shuffle
  block_by: [vacuum_kpa]
record: [midi, arm, mocap]
"""
RANDOM_RIG = "kind: sim\nseed: 0\nworld: {preset: default}\n"
LEAN_RIG = "kind: sim\nseed: 0\nworld: {preset: default, out_dt_s: 0.005, arm_rate_hz: 125}\n"


def _rss_mb() -> float:
    """Current resident set size (Linux /proc; falls back to the peak elsewhere)."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
        return pages * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        return _peak_rss_mb()


def _peak_rss_mb() -> float:
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if sys.platform == "darwin" else peak / 1024  # bytes on macOS, KiB on Linux


def _folder_bytes(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def _timed(fn: Any) -> tuple[Any, float, float]:
    wall, cpu = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - wall, time.process_time() - cpu


def raw_simulator(trials: list[Any], rig: Any, seed: int) -> dict[str, float]:
    """The batch integrator alone on the sweep's own presses: what the physics costs."""
    from pianobot.rig.sim import make_world

    world = make_world(rig.world, seed)
    items = sorted(((t.press(), t.vacuum_kpa) for t in trials), key=lambda x: world._horizon_s(x[0]))
    world.simulate([items[0][0]], items[0][1])  # compile / load the kernels first

    def run() -> None:
        for i in range(0, len(items), 64):
            chunk = items[i : i + 64]
            world.simulate([p for p, _ in chunk], [v for _, v in chunk])

    _, wall, cpu = _timed(run)
    return {"trials_per_s_wall": len(items) / wall, "trials_per_s_cpu": len(items) / cpu}


def storage_floor(run_path: Path, trials: int, block: int = 128) -> dict[str, float]:
    """What storing the run's sample rows costs alone: encode them as parts (one per `block`
    trials' worth of rows) and compact them into one file, as the store does, from memory."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from pianobot.store import encode_part
    from pianobot.store.layout import parquet_options

    table = pq.read_table(run_path / "samples.parquet")
    per_part = max(1, table.num_rows * block // max(trials, 1))

    def store() -> None:
        parts = [encode_part(table.slice(i, per_part).drop_columns(["run_id"]), "samples", "bench")
                 for i in range(0, table.num_rows, per_part)]
        out = pa.BufferOutputStream()
        with pq.ParquetWriter(out, table.schema, **parquet_options(table.schema)) as writer:
            for part in parts:
                f = pq.ParquetFile(pa.BufferReader(part), read_dictionary=["run_id", "trial_id", "source"])
                for g in range(f.num_row_groups):
                    writer.write_table(f.read_row_group(g).cast(table.schema))

    _, wall, cpu = _timed(store)
    return {"rows": table.num_rows, "trials_per_s_wall": trials / wall, "trials_per_s_cpu": trials / cpu}


def _sweep(spec: Path, data: Path, **kwargs: Any) -> tuple[Any, float, float]:
    from pianobot.run import run_sweep

    return _timed(lambda: run_sweep(spec, data_dir=data, progress=False, **kwargs))


def scenario_grid(quick: bool) -> dict[str, Any]:
    """The full soft-finger grid, every stream: sweep vs raw simulator vs the old path."""
    from pianobot.executor import ExecutorSettings
    from pianobot.rig import Rig
    from pianobot.run import prepare_sweep
    from pianobot.store import load_run

    with tempfile.TemporaryDirectory() as tmp:
        spec = _grid_spec(Path(tmp), 3 if quick else 15)
        prepared = prepare_sweep(spec)
        raw = raw_simulator(prepared.trials, prepared.rig, prepared.seed)
        outcome, wall, cpu = _sweep(spec, Path(tmp) / "data", executor=ExecutorSettings(workers=1))
        peak_rss_mb = _peak_rss_mb()
        run = load_run(outcome.run_id, Path(tmp) / "data")
        sources = run.table("samples", columns=["source"])["source"].value_counts().to_dict()
        floor = storage_floor(run.path, outcome.trials)
        # The one-keystroke-at-a-time path (how every simulated sweep ran before), on a fifth.
        old_spec = _grid_spec(Path(tmp) / "old", 3)
        original = Rig.batches
        Rig.batches = property(lambda self: False)  # type: ignore[method-assign, assignment]
        try:
            old, old_wall, old_cpu = _sweep(old_spec, Path(tmp) / "old-data",
                                            executor=ExecutorSettings(workers=1))
        finally:
            Rig.batches = original  # type: ignore[method-assign]
        n = outcome.trials
        return {
            "spec": str(GRID.relative_to(REPO)), "trials": n, "status": outcome.status,
            "wall_s": round(wall, 2), "cpu_s": round(cpu, 2),
            "trials_per_s_wall": round(n / wall, 1), "trials_per_s_cpu": round(n / cpu, 1),
            "raw_simulator_trials_per_s_wall": round(raw["trials_per_s_wall"], 1),
            "raw_simulator_trials_per_s_cpu": round(raw["trials_per_s_cpu"], 1),
            "ratio_to_raw_simulator_wall": round(n / wall / raw["trials_per_s_wall"], 3),
            "ratio_to_raw_simulator_cpu": round(n / cpu / raw["trials_per_s_cpu"], 3),
            "old_path_trials": old.trials,
            "old_path_trials_per_s_wall": round(old.trials / old_wall, 1),
            "old_path_trials_per_s_cpu": round(old.trials / old_cpu, 1),
            "speedup_over_old_path_wall": round((n / wall) / (old.trials / old_wall), 2),
            "speedup_over_old_path_cpu": round((n / cpu) / (old.trials / old_cpu), 2),
            "storing_samples_only_trials_per_s_cpu": round(floor["trials_per_s_cpu"], 1),
            "storing_samples_only_vs_raw_simulator_cpu": round(
                floor["trials_per_s_cpu"] / raw["trials_per_s_cpu"], 3),
            "peak_rss_mb": round(peak_rss_mb, 1),
            "rows": {"trials": int(len(run.trials)), "samples_by_source": sources,
                     "midi": int(len(run.midi))},
            "bytes_on_disk": _folder_bytes(run.path),
        }


def _grid_spec(folder: Path, speeds: int) -> Path:
    """The study grid with `speeds` down speeds (15: the whole grid), its rig files alongside."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "rigs").mkdir(exist_ok=True)
    for rig in (GRID.parent / "rigs").glob("*.yaml"):
        (folder / "rigs" / rig.name).write_text(rig.read_text())
    spec = folder / GRID.name
    spec.write_text(GRID.read_text().replace("num: 15", f"num: {speeds}"))
    return spec


def scenario_random(samples: int, lean: bool = False) -> dict[str, Any]:
    """A long random sweep, every stream: throughput against the raw simulator, RSS along it."""
    from pianobot.executor import ExecutorSettings
    from pianobot.run import TrialDone, prepare_sweep, run_sweep

    folder = Path(tempfile.mkdtemp(prefix="pianobot-bench-"))
    try:
        (folder / "rig.yaml").write_text(LEAN_RIG if lean else RANDOM_RIG)
        spec = folder / "random.yaml"
        spec.write_text(RANDOM_SPEC.format(samples=samples, distance=0.0 if lean else 0.01))
        prepared = prepare_sweep(spec)
        probe = prepared.trials[: min(len(prepared.trials), 5000)]
        raw = raw_simulator(probe, prepared.rig, prepared.seed)
        del prepared, probe
        step = max(1, samples // 10)
        rss: list[tuple[int, float]] = []

        def sample(record: Any) -> None:
            if isinstance(record, TrialDone) and int(record.data.row["index"]) % step == 0:
                rss.append((int(record.data.row["index"]), round(_rss_mb(), 1)))

        outcome, wall, cpu = _timed(lambda: run_sweep(
            spec, data_dir=folder / "data", progress=False, subscribers=[sample],
            executor=ExecutorSettings(workers=1)))
        peak_rss_mb = _peak_rss_mb()
        floor = storage_floor(outcome.path, outcome.trials) if samples <= 20_000 else None
        return {
            "trials": samples, "status": outcome.status, "completed": outcome.trials,
            "world": "default, truth at 200 Hz, arm at 125 Hz" if lean else "default",
            "wall_s": round(wall, 2), "cpu_s": round(cpu, 2),
            "trials_per_s_wall": round(samples / wall, 1), "trials_per_s_cpu": round(samples / cpu, 1),
            "raw_simulator_trials_per_s_wall": round(raw["trials_per_s_wall"], 1),
            "raw_simulator_trials_per_s_cpu": round(raw["trials_per_s_cpu"], 1),
            "ratio_to_raw_simulator_wall": round(samples / wall / raw["trials_per_s_wall"], 3),
            "ratio_to_raw_simulator_cpu": round(samples / cpu / raw["trials_per_s_cpu"], 3),
            "storing_samples_only_trials_per_s_cpu": (
                None if floor is None else round(floor["trials_per_s_cpu"], 1)),
            "peak_rss_mb": round(peak_rss_mb, 1),
            "rss_mb_by_trial": rss,
            "rss_growth_mb_after_first_tenth": round(rss[-1][1] - rss[1][1], 1) if len(rss) > 2 else None,
            "bytes_on_disk": _folder_bytes(folder / "data"),
        }
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def scenario_dask(quick: bool) -> dict[str, Any]:
    """The same sweep on 1 worker (this process) and on a local cluster of 2 processes."""
    from pianobot.executor import ExecutorSettings, open_executor
    from pianobot.store import load_run

    with tempfile.TemporaryDirectory() as tmp:
        spec = _grid_spec(Path(tmp), 1 if quick else 5)
        _, start_s, _ = _timed(lambda: open_executor(ExecutorSettings(workers=2)))
        _sweep(spec, Path(tmp) / "warm", executor=ExecutorSettings(workers=2), batch_trials=64)
        one, one_wall, _ = _sweep(spec, Path(tmp) / "one", executor=ExecutorSettings(workers=1),
                                  batch_trials=64)
        two, two_wall, _ = _sweep(spec, Path(tmp) / "two", executor=ExecutorSettings(workers=2),
                                  batch_trials=64)
        a = load_run(one.run_id, Path(tmp) / "one").trials.sort_values("trial_id").reset_index(drop=True)
        b = load_run(two.run_id, Path(tmp) / "two").trials.sort_values("trial_id").reset_index(drop=True)
        cols = [c for c in a.columns if c != "run_id"]
        return {
            "trials": one.trials, "cluster_start_s": round(start_s, 2),
            "one_worker_wall_s": round(one_wall, 2), "two_processes_wall_s": round(two_wall, 2),
            "speedup": round(one_wall / two_wall, 2),
            "identical_trials": bool(a[cols].equals(b[cols])),
            "identify_bootstrap": "not wired yet: waits for issue 10's analysis reorganisation",
            "discovery_candidates": "not wired yet: waits for issue 10's analysis reorganisation",
        }


def scenario_lab_time() -> dict[str, Any]:
    """The study grid's planned lab time three ways."""
    from pianobot.physics.trajectory import press_duration_s
    from pianobot.plan import lab_time
    from pianobot.plan.approach import with_fast_approach
    from pianobot.run import prepare_sweep

    prepared = prepare_sweep(GRID)
    trials, rig = prepared.trials, prepared.rig
    study_s = sum(press_duration_s(t.press()) + 2 * STUDY_SLEEP_S for t in trials)
    plain = lab_time(trials, rig)
    fast = lab_time(with_fast_approach(trials, rig), rig)
    in_contact_s = sum(t.depth_m / t.down_velocity_mps + t.depth_m / t.up_velocity_mps for t in trials)
    return {
        "trials": len(trials),
        "study_script_h": round(study_s / 3600, 3),
        "as_specified_h": round(plain.total_s / 3600, 3),
        "fast_approach_h": round(fast.total_s / 3600, 3),
        "as_specified_vs_study": round(plain.total_s / study_s, 3),
        "fast_vs_study": round(fast.total_s / study_s, 3),
        "fast_vs_as_specified": round(fast.total_s / plain.total_s, 3),
        "depth_at_contact_speeds_h": round(in_contact_s / 3600, 3),
        "depth_at_contact_speeds_vs_study": round(in_contact_s / study_s, 3),
        "fast_breakdown_s": {k: round(v, 1) for k, v in fast.to_dict().items()},
        "approach_settings": rig.approach.model_dump(),
    }


def _child(name: str, *flags: str) -> dict[str, Any]:
    """Run one scenario in a fresh interpreter and return its JSON."""
    args = [sys.executable, __file__, "--scenario", name, *flags]
    done = subprocess.run(args, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"scenario {name} failed:\n{done.stderr}")
    result: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


SCENARIOS = ("grid", "random", "random_large", "rss_1m", "dask", "lab_time")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, to check the script")
    parser.add_argument("--large", action="store_true", help="also 100,000 and 1,000,000 trials")
    parser.add_argument("--scenario", choices=SCENARIOS, help=argparse.SUPPRESS)
    args = parser.parse_args()
    quick = ("--quick",) if args.quick else ()
    if args.scenario is not None:
        runners = {
            "grid": lambda: scenario_grid(args.quick),
            "random": lambda: scenario_random(1_000 if args.quick else 10_000),
            "random_large": lambda: scenario_random(100_000),
            "rss_1m": lambda: scenario_random(1_000_000, lean=True),
            "dask": lambda: scenario_dask(args.quick),
            "lab_time": scenario_lab_time,
        }
        print(json.dumps(runners[args.scenario]()))
        return
    results: dict[str, Any] = {
        "benchmark": "sweep", "quick": args.quick, "large": args.large,
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                    "platform": platform.platform(), "load_average_start": os.getloadavg()},
    }
    if args.large:
        results["random_100k"] = _child("random_large")
        results["rss_1m"] = _child("rss_1m")
    else:
        for name in ("grid", "random", "dask", "lab_time"):
            results[name] = _child(name, *quick)
    results["machine"]["load_average_end"] = os.getloadavg()
    text = json.dumps(results, indent=2)
    print(text)
    if not args.quick:
        RESULTS.mkdir(parents=True, exist_ok=True)
        (RESULTS / ("sweep_large.json" if args.large else "sweep.json")).write_text(text + "\n")


if __name__ == "__main__":
    main()
