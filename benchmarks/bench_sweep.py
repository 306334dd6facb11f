"""Sweep benchmark: the study's full soft-finger grid end to end, and a 100,000-trial sweep.

    python benchmarks/bench_sweep.py            # both scenarios; JSON on stdout
    python benchmarks/bench_sweep.py --quick    # 1/10 of each, to check the script itself

1. `experiments/soft_finger_grid.yaml` (2,025 trials) on the sim rig with every stream recorded
   (MIDI, arm, mocap, sim truth): trials/s, peak RSS, rows and bytes written, and lab time three
   ways — pianobot's plan estimate, the simulated run clock, and the study's own script timing
   (a 0.5 s sleep before and after every press plus the two moveLs).
2. A random sweep of 100,000 trials with trial records only (`record: [midi]`) on the linear
   sim world: trials/s and RSS sampled every 10,000 trials, to show memory stays flat.

Each scenario runs in its own process so its peak RSS is its own. Results also go to
`benchmarks/results/sweep.json`.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results" / "sweep.json"
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
    vacuum_kpa: {{low: -80, high: 0}}
    down_velocity_mps: {{low: 0.01, high: 0.06}}
    acceleration_mps2: {{low: 0.1, high: 1.0}}
    depth_m: {{low: 0.02, high: 0.035}}
  fixed: {{distance_m: 0.05, hold_s: 0.0}}
  order: as-listed
record: [midi]
"""
RANDOM_RIG = "kind: sim\nseed: 0\nworld: {preset: linear}\n"


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


def _study_script_time_s(trials: list[Any]) -> float:
    """The study's loop: sleep 0.5, moveL down, moveL up, sleep 0.5 — per press, nothing else."""
    from pianobot.physics.trajectory import press_duration_s

    return sum(press_duration_s(t.press()) + 2 * STUDY_SLEEP_S for t in trials)


def scenario_grid(fraction: float) -> dict[str, Any]:
    """The full soft-finger grid with every stream, end to end (spec → compacted Parquet)."""
    from pianobot.plan import lab_time
    from pianobot.run import TrialDone, prepare_sweep, run_sweep
    from pianobot.store import load_run

    prepared = prepare_sweep(GRID)
    trials = prepared.trials
    with tempfile.TemporaryDirectory() as tmp:
        spec = GRID
        if fraction < 1.0:  # --quick: the same grid with fewer speeds
            text = GRID.read_text().replace("num: 15", f"num: {max(2, round(15 * fraction))}")
            spec = Path(tmp) / "soft_finger_grid.yaml"
            spec.write_text(text)
            for rig in (GRID.parent / "rigs").glob("*.yaml"):
                (Path(tmp) / "rigs").mkdir(exist_ok=True)
                (Path(tmp) / "rigs" / rig.name).write_text(rig.read_text())
            prepared = prepare_sweep(spec)
            trials = prepared.trials
        rss: list[tuple[int, float]] = []

        def sample(record: Any) -> None:
            if isinstance(record, TrialDone) and int(record.data.row["index"]) % 250 == 0:
                rss.append((int(record.data.row["index"]), round(_rss_mb(), 1)))

        start = time.perf_counter()
        outcome = run_sweep(spec, data_dir=Path(tmp) / "data", progress=False, subscribers=[sample])
        wall_s = time.perf_counter() - start
        peak_rss_mb = _peak_rss_mb()  # before this script reads the results back
        run = load_run(outcome.run_id, Path(tmp) / "data")
        sources = pq.read_table(run.path / "samples.parquet", columns=["source"], read_dictionary=["source"])
        by_source = sources.column("source").value_counts().to_pylist()
        planned = lab_time(trials, prepared.rig)
        return {
            "spec": str(GRID.relative_to(REPO)),
            "trials": len(trials),
            "status": outcome.status,
            "silent": outcome.silent,
            "wall_s": round(wall_s, 2),
            "trials_per_s": round(len(trials) / wall_s, 1),
            "peak_rss_mb": round(peak_rss_mb, 1),
            "rss_mb_by_trial": rss,
            "rows": {
                "trials": int(len(run.trials)),
                "samples": int(sources.num_rows),
                "samples_by_source": {str(e["values"]): int(e["counts"]) for e in by_source},
                "midi": int(len(run.midi)),
            },
            "bytes_on_disk": _folder_bytes(run.path),
            "lab_time_h": {
                "planned_estimate": round(planned.total_s / 3600, 3),
                "simulated_run_clock": round(outcome.lab_time_s / 3600, 3),
                "study_script": round(_study_script_time_s(trials) / 3600, 3),
            },
            "lab_time_breakdown_s": {k: round(v, 1) for k, v in planned.to_dict().items()},
        }


def scenario_random(samples: int) -> dict[str, Any]:
    """A long random sweep recording trial rows only: memory must not grow with the trial count."""
    from pianobot.run import TrialDone, run_sweep
    from pianobot.store import load_run

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "rig.yaml").write_text(RANDOM_RIG)
        spec = folder / "random.yaml"
        spec.write_text(RANDOM_SPEC.format(samples=samples))
        step = max(1, samples // 10)
        rss: list[tuple[int, float]] = []

        def sample(record: Any) -> None:
            if isinstance(record, TrialDone) and int(record.data.row["index"]) % step == 0:
                rss.append((int(record.data.row["index"]), round(_rss_mb(), 1)))

        start = time.perf_counter()
        outcome = run_sweep(spec, data_dir=folder / "data", progress=False, subscribers=[sample])
        wall_s = time.perf_counter() - start
        peak_rss_mb = _peak_rss_mb()
        run = load_run(outcome.run_id, folder / "data")
        return {
            "trials": samples,
            "status": outcome.status,
            "completed": outcome.trials,
            "wall_s": round(wall_s, 2),
            "trials_per_s": round(samples / wall_s, 1),
            "peak_rss_mb": round(peak_rss_mb, 1),
            "rss_mb_by_trial": rss,
            "rss_growth_mb_after_first_tenth": round(rss[-1][1] - rss[1][1], 1) if len(rss) > 2 else None,
            "bytes_on_disk": _folder_bytes(run.path),
            "samples_rows": int(len(run.table("samples", columns=["t_s"]))),
        }


def _child(name: str, quick: bool) -> dict[str, Any]:
    """Run one scenario in a fresh interpreter and return its JSON."""
    args = [sys.executable, __file__, "--scenario", name] + (["--quick"] if quick else [])
    done = subprocess.run(args, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"scenario {name} failed:\n{done.stderr}")
    result: dict[str, Any] = json.loads(done.stdout)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a tenth of each scenario")
    parser.add_argument("--scenario", choices=("grid", "random"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.scenario == "grid":
        print(json.dumps(scenario_grid(0.15 if args.quick else 1.0)))
        return
    if args.scenario == "random":
        print(json.dumps(scenario_random(10_000 if args.quick else 100_000)))
        return
    results = {
        "benchmark": "sweep",
        "quick": args.quick,
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "platform": platform.platform()},
        "grid": _child("grid", args.quick),
        "random": _child("random", args.quick),
    }
    text = json.dumps(results, indent=2)
    print(text)
    if not args.quick:
        RESULTS.parent.mkdir(parents=True, exist_ok=True)
        RESULTS.write_text(text + "\n")


if __name__ == "__main__":
    main()
