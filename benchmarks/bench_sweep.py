"""Sweep benchmark: simulated sweeps against the physics they run, side by side in one run.

    python benchmarks/bench_sweep.py            # grid, 10,000 random, lab time
    python benchmarks/bench_sweep.py --large    # also 100,000 random trials and 1,000,000 for RSS
    python benchmarks/bench_sweep.py --quick    # small sizes, to check the script itself
    python benchmarks/bench_sweep.py --only random --random-trials 1000 --baseline main
                                                # beside the pianobot of another git revision

Every sweep stores every stream (MIDI, arm, mocap and the simulated truth). Figures:

1. `grid`: the study's 2,025-trial grid (experiments/soft_finger_grid.yaml), one worker. Its
   throughput is compared, in the same process, with (a) the raw simulator on the same 2,025
   presses (the batch integrator alone, sorted into batches of similar length: what the physics
   needs) and (b) the one-keystroke-at-a-time path the sweep used before (on 405 of the trials).
2. `random`: a random sweep (10,000 trials; 100,000 with --large) of short strokes from 10 mm
   above the key, the same comparison with the raw simulator, RSS sampled along the run, and
   the CPU per trial of each phase (physics, keystrokes, parts, compaction).
3. `rss_1m` (--large): 1,000,000 trials, RSS every 100,000 trials (bounded: no per-trial
   state grows). The world samples its truth at 200 Hz and the arm at 125 Hz there, to keep the
   run's data near 10 GB on disk.
4. `lab_time`: the study grid's planned lab time as specified, with `approach: fast`, and by
   the study's own script (0.5 s sleep before and after each press plus the two moveLs); where
   the fast plan's press time goes; what a settle worked out from the finger's own mode would
   save, checked in the simulated world; and `fast_vs_study_bounds`, how low a fast plan gets
   with no settle, a 2 mm clearance and UR5 travel moves at 1 m/s (not the same data: bounds).

`--baseline REF` runs grid and random also with the pianobot of git revision REF (baseline,
this, baseline, this; the better run of each kept) and reports the speed-up over it. Dask (2 processes
against 1): benchmarks/bench_dask.py.

Times are wall-clock and CPU (this process only). The
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


RAW_LANES = (16, 64)  # batch sizes the raw simulator is timed with; the faster one counts


def raw_simulator(trials: list[Any], rig: Any, seed: int, repeat: int = 2) -> dict[str, float]:
    """The batch integrator alone on the sweep's own presses: what the physics costs.

    All presses sorted by length, then run in batches of each of `RAW_LANES` keystrokes (16,
    the kernel's SIMD block, is the faster here: a batch's output stays in cache; 64 was the
    measure before session 5), each batch dropped at once. One untimed pass first (kernels
    compiled or loaded from numba's cache, memory touched), then the best of `repeat`.
    """
    from pianobot.rig.sim import make_world

    world = make_world(rig.world, seed)
    items = sorted(((t.press(), t.vacuum_kpa) for t in trials), key=lambda x: world._horizon_s(x[0]))
    out: dict[str, float] = {}
    for lanes in RAW_LANES:

        def run(lanes: int = lanes) -> None:
            for i in range(0, len(items), lanes):
                chunk = items[i : i + lanes]
                world.simulate([p for p, _ in chunk], [v for _, v in chunk])

        run()
        times = [_timed(run)[1:] for _ in range(max(1, repeat))]
        rate_cpu = len(items) / min(t[1] for t in times)
        out[f"trials_per_s_cpu_{lanes}_lanes"] = rate_cpu
        if rate_cpu > out.get("trials_per_s_cpu", 0.0):
            out.update(trials_per_s_wall=len(items) / min(t[0] for t in times),
                       trials_per_s_cpu=rate_cpu, lanes=lanes)
    return out


def _by_lanes(raw: dict[str, float]) -> dict[str, float]:
    """The raw simulator's CPU rate at each batch size it was timed with."""
    return {str(lanes): round(raw[f"trials_per_s_cpu_{lanes}_lanes"], 1) for lanes in RAW_LANES}


PHASES = {  # (module, owner, method): what a simulated sweep spends its CPU on
    "physics (prefetch: the block's truth in batches)": ("pianobot.rig.station", "Rig", "prepare"),
    "keystrokes (station, observation, readout, records)": ("pianobot.run.runner", "Runner", "run_block"),
    "parts (tables, encoding, writes, journal)": ("pianobot.run.sink", "StoreSink", "flush"),
    "compaction (check, read parts, one file per table)": ("pianobot.store.writer", "RunWriter", "compact"),
}


def phase_timer() -> tuple[dict[str, float], Any]:
    """CPU seconds per phase of a sweep (wrapping the methods above); call the second item to undo."""
    import importlib

    spent = dict.fromkeys(PHASES, 0.0)
    undo = []
    for label, (module, owner, name) in PHASES.items():
        cls = getattr(importlib.import_module(module), owner)
        original = getattr(cls, name)

        def timed(*args: Any, _f: Any = original, _label: str = label, **kwargs: Any) -> Any:
            cpu = time.process_time()
            try:
                return _f(*args, **kwargs)
            finally:
                spent[_label] += time.process_time() - cpu

        setattr(cls, name, timed)
        undo.append((cls, name, original))

    def restore() -> None:
        for cls, name, original in undo:
            setattr(cls, name, original)

    return spent, restore


def storage_floor(run_path: Path, trials: int, block: int = 128) -> dict[str, float]:
    """What storing the run's sample rows costs alone: encode them as the store does, one file
    per `block` trials' worth of rows (ids as dictionaries), from memory."""
    import pyarrow.parquet as pq

    from pianobot.store import encode_part

    text = ["run_id", "trial_id", "source"]
    folder = run_path / "samples"  # samples.parquet: a run of an older pianobot (a baseline)
    table = pq.read_table(folder if folder.is_dir() else run_path / "samples.parquet", read_dictionary=text)
    per_part = max(1, table.num_rows * block // max(trials, 1))

    def store() -> None:
        for i in range(0, table.num_rows, per_part):
            encode_part(table.slice(i, per_part).drop_columns(["run_id"]), "samples", "bench")

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
            "raw_simulator_by_lanes_trials_per_s_cpu": _by_lanes(raw),
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


def scenario_random(samples: int, lean: bool = False, breakdown: bool = True) -> dict[str, Any]:
    """A long random sweep, every stream: throughput against the raw simulator, RSS along it,
    and (`breakdown`) the CPU per trial of each phase (physics, keystrokes, parts, compaction)."""
    from pianobot.executor import ExecutorSettings
    from pianobot.run import TrialDone, prepare_sweep, run_sweep

    folder = Path(tempfile.mkdtemp(prefix="pianobot-bench-"))
    try:
        (folder / "rig.yaml").write_text(LEAN_RIG if lean else RANDOM_RIG)
        spec = folder / "random.yaml"
        spec.write_text(RANDOM_SPEC.format(samples=samples, distance=0.0 if lean else 0.01))
        prepared = prepare_sweep(spec, max_trials=samples)
        probe = prepared.trials[: min(len(prepared.trials), 5000)]
        raw = raw_simulator(probe, prepared.rig, prepared.seed)
        del prepared, probe
        step = max(1, samples // 10)
        rss: list[tuple[int, float]] = []

        def sample(record: Any) -> None:
            if isinstance(record, TrialDone) and int(record.data.row["index"]) % step == 0:
                rss.append((int(record.data.row["index"]), round(_rss_mb(), 1)))
                # Also as it goes (stderr), so a run stopped early still shows its memory.
                print(f"trial {rss[-1][0]}: RSS {rss[-1][1]} MB, {time.process_time():.0f} s CPU",
                      file=sys.stderr, flush=True)

        spent, restore = phase_timer() if breakdown else ({}, lambda: None)
        try:
            outcome, wall, cpu = _timed(lambda: run_sweep(
                spec, data_dir=folder / "data", progress=False, subscribers=[sample],
                executor=ExecutorSettings(workers=1), max_trials=samples))
        finally:
            restore()
        peak_rss_mb = _peak_rss_mb()
        done = max(outcome.trials, 1)  # rates over the trials run (a stopped run ran fewer)
        floor = storage_floor(outcome.path, outcome.trials) if samples <= 20_000 else None
        rows = floor["rows"] if floor is not None else None
        return {
            "trials": samples, "status": outcome.status, "completed": outcome.trials,
            "world": "default, truth at 200 Hz, arm at 125 Hz" if lean else "default",
            "wall_s": round(wall, 2), "cpu_s": round(cpu, 2),
            "trials_per_s_wall": round(done / wall, 1), "trials_per_s_cpu": round(done / cpu, 1),
            "raw_simulator_trials_per_s_wall": round(raw["trials_per_s_wall"], 1),
            "raw_simulator_trials_per_s_cpu": round(raw["trials_per_s_cpu"], 1),
            "raw_simulator_by_lanes_trials_per_s_cpu": _by_lanes(raw),
            "ratio_to_raw_simulator_wall": round(done / wall / raw["trials_per_s_wall"], 3),
            "ratio_to_raw_simulator_cpu": round(done / cpu / raw["trials_per_s_cpu"], 3),
            "storing_samples_only_trials_per_s_cpu": (
                None if floor is None else round(floor["trials_per_s_cpu"], 1)),
            "storing_samples_only_vs_raw_simulator_cpu": (
                None if floor is None else round(floor["trials_per_s_cpu"] / raw["trials_per_s_cpu"], 3)),
            "sample_rows_per_trial": None if rows is None else round(rows / done),
            "cpu_us_per_trial": round(cpu / done * 1e6),
            "raw_simulator_cpu_us_per_trial": round(1e6 / raw["trials_per_s_cpu"]),
            "breakdown_cpu_us_per_trial": {k: round(v / done * 1e6) for k, v in spent.items()},
            "peak_rss_mb": round(peak_rss_mb, 1),
            "rss_mb_by_trial": rss,
            "rss_growth_mb_after_first_tenth": round(rss[-1][1] - rss[1][1], 1) if len(rss) > 2 else None,
            "bytes_on_disk": _folder_bytes(folder / "data"),
        }
    finally:
        shutil.rmtree(folder, ignore_errors=True)


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
        "fast_presses_h": _press_parts_h(with_fast_approach(trials, rig)),
        "approach_settings": rig.approach.model_dump(),
        "settle_from_physics": _settle_from_physics(trials, rig, study_s, fast.total_s),
        "fast_vs_study_bounds": _fast_bounds(trials, rig, study_s),
    }


#: Fast plans that drop what the default keeps, each against the study's script: how low the
#: exact-kinematics fast approach can go on this grid at all.
FAST_BOUNDS = {
    "no_settle": {"settle_s": 0.0},
    "no_settle_2mm_clearance": {"settle_s": 0.0, "clearance_m": 0.002},
    "no_settle_2mm_clearance_travel_1mps_3mps2": {"settle_s": 0.0, "clearance_m": 0.002,
                                                  "velocity_mps": 1.0, "acceleration_mps2": 3.0},
}


def _fast_bounds(trials: list[Any], rig: Any, study_s: float) -> dict[str, float]:
    """The fast plan's lab time against the study's script with no settle before contact (the
    finger then still rings from the stop: not the same data), a 2 mm clearance, and UR5
    travel moves at 1 m/s and 3 m/s². What stays is the spec's own motion in contact, its
    acceleration phases and the pauses between presses."""
    from pianobot.plan import lab_time
    from pianobot.plan.approach import with_fast_approach

    out = {}
    for name, change in FAST_BOUNDS.items():
        plan_rig = rig.model_copy(update={"approach": rig.approach.model_copy(update=change)})
        out[name] = round(lab_time(with_fast_approach(trials, plan_rig), plan_rig).total_s / study_s, 3)
    return out


def _press_parts_h(trials: list[Any]) -> dict[str, float]:
    """Where a fast plan's press time goes (hours over the plan)."""
    from pianobot.physics.trajectory import contact_time_s, press_timing

    parts = dict.fromkeys(("fast_approach", "spec_motion_before_contact", "down_in_contact",
                           "hold", "up_until_clear", "fast_retract"), 0.0)
    for t in trials:
        press = t.press()
        tm = press_timing(press)
        contact = contact_time_s(press)
        parts["fast_approach"] += tm.t_down_start_s
        parts["spec_motion_before_contact"] += contact - tm.t_down_start_s
        parts["down_in_contact"] += tm.t_down_end_s - contact
        parts["hold"] += tm.t_hold_end_s - tm.t_down_end_s
        parts["up_until_clear"] += tm.t_lifted_s - tm.t_hold_end_s
        parts["fast_retract"] += tm.t_end_s - tm.t_lifted_s
    return {k: round(v / 3600, 3) for k, v in parts.items()}


def _settle_from_physics(trials: list[Any], rig: Any, study_s: float, fast_s: float) -> dict[str, Any]:
    """What a per-trial settle worked out from the finger's own mode would save, and whether
    the contact state stays within noise with it (simulated, on a spread of the grid's trials).

    The free finger (fingertip mass m1 on the arm through k0, c0) rings at ω0 = √(k0/m1) and
    decays with τ = 2·m1/c0. A step Δa in the arm's acceleration leaves a fingertip speed swing
    of Δa/ω0; the fast move's stop and the spec move's start are two such steps (a_travel +
    a_spec, worst case in phase). The contact state is within noise once that swing has decayed
    below max(2 % of the contact speed, the speed noise of two mocap frames):
    settle = τ · ln(swing / tolerance).
    """
    import math

    import numpy as np

    from pianobot.physics.approach import ApproachSettings, plan_fast_moves
    from pianobot.physics.msd import MSDParams
    from pianobot.physics.trajectory import Press, contact_speed_mps, press_duration_s
    from pianobot.physics.world import World
    from pianobot.plan.approach import approach_settings

    finger = MSDParams()
    base = approach_settings(rig)
    mocap = World.default().config.mocap
    noise_mps = math.sqrt(2.0) * mocap.noise_m * mocap.rate_hz
    tau_s = 2.0 * finger.m1_kg / finger.c0_over_c1 / finger.c1_nspm

    def settle_s(t: Any) -> float:
        k0 = finger.at(t.vacuum_kpa).k0_npm
        swing = (base.acceleration_mps2 + t.acceleration_mps2) / math.sqrt(k0 / finger.m1_kg)
        tolerance = max(0.02 * contact_speed_mps(t.press()), noise_mps)
        return max(0.0, tau_s * math.log(swing / tolerance))

    settles = np.array([settle_s(t) for t in trials])
    c = {n: np.array([getattr(t, n) for t in trials], dtype=float) for n in (
        "distance_m", "depth_m", "down_velocity_mps", "up_velocity_mps", "acceleration_mps2")}
    per_trial = ApproachSettings(base.velocity_mps, base.acceleration_mps2, base.clearance_m,
                                 settles)  # type: ignore[arg-type]  (columns broadcast)
    moves = plan_fast_moves(c["distance_m"], c["depth_m"], c["down_velocity_mps"],
                            c["up_velocity_mps"], c["acceleration_mps2"], per_trial)
    presses = [Press(t.distance_m, t.depth_m, t.down_velocity_mps, t.up_velocity_mps,
                     t.acceleration_mps2, t.hold_s, approach_m=float(a), retract_m=float(r),
                     travel_velocity_mps=base.velocity_mps,
                     travel_acceleration_mps2=base.acceleration_mps2)
                 for t, a, r in zip(trials, moves.approach_m, moves.retract_m, strict=True)]
    fixed = plan_fast_moves(c["distance_m"], c["depth_m"], c["down_velocity_mps"],
                            c["up_velocity_mps"], c["acceleration_mps2"], base)
    saved_s = sum(
        press_duration_s(Press(t.distance_m, t.depth_m, t.down_velocity_mps, t.up_velocity_mps,
                               t.acceleration_mps2, t.hold_s, approach_m=float(a), retract_m=float(r),
                               travel_velocity_mps=base.velocity_mps,
                               travel_acceleration_mps2=base.acceleration_mps2))
        for t, a, r in zip(trials, fixed.approach_m, fixed.retract_m, strict=True)
    ) - sum(press_duration_s(p) for p in presses)
    # The check: simulated fingertip speed at contact, per-trial settle against the spec's press.
    world = World.default(seed=3)
    picks = sorted({(t.down_velocity_mps, t.acceleration_mps2, t.vacuum_kpa, t.depth_m): i
                    for i, t in enumerate(trials)}.values())[::max(1, len(trials) // 60)]
    spec = [trials[i].press() for i in picks]
    vac = [trials[i].vacuum_kpa for i in picks]
    keys = [f"k{i}" for i in picks]
    blocks = [f"{v:g}" for v in vac]
    plain = world.keystrokes(spec, vac, keys=keys, blocks=blocks)
    quick = world.keystrokes([presses[i] for i in picks], vac, keys=keys, blocks=blocks)
    worst = 0.0
    for p, a, b in zip(spec, plain, quick, strict=True):
        va, vb = _tip_speed_at_contact(a, p.distance_m), _tip_speed_at_contact(b, p.distance_m)
        tolerance = max(0.02 * abs(va), noise_mps)
        worst = max(worst, abs(vb - va) / tolerance)
    return {
        "tau_s": round(tau_s, 3), "settle_s_range": [round(float(settles.min()), 2),
                                                     round(float(settles.max()), 2)],
        "settle_s_mean": round(float(settles.mean()), 2),
        "saved_h": round(saved_s / 3600, 3),
        "fast_vs_study": round((fast_s - saved_s) / study_s, 3),
        "checked_trials": len(picks),
        "worst_tip_speed_error_in_tolerances": round(worst, 2),  # <= 1: within noise
    }


def _tip_speed_at_contact(stroke: Any, distance_m: float) -> float:
    """The fingertip's true speed when it meets the key (its truth trace)."""
    import numpy as np

    t = np.asarray(stroke.truth_t_s)
    gap = np.asarray(stroke.truth_x1_m) - np.asarray(stroke.truth_x2_m)
    k = int(np.argmax(gap >= distance_m))
    f = (distance_m - gap[k - 1]) / (gap[k] - gap[k - 1])
    v1 = np.gradient(np.asarray(stroke.truth_x1_m), t)
    return float(v1[k - 1] + f * (v1[k] - v1[k - 1]))


def _child(name: str, *flags: str, code: Path | None = None) -> dict[str, Any]:
    """Run one scenario in a fresh interpreter and return its JSON; `code`: a folder holding
    another version of the `pianobot` package to run it with (a baseline)."""
    args = [sys.executable, __file__, "--scenario", name, *flags]
    env = dict(os.environ)
    if code is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(code), *filter(None, [env.get("PYTHONPATH")])])
    done = subprocess.run(args, capture_output=True, text=True, check=False, env=env)
    if done.returncode != 0:
        raise SystemExit(f"scenario {name} failed:\n{done.stderr}")
    result: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


SCENARIOS = ("grid", "random", "random_large", "rss_1m", "lab_time")


def _export(ref: str, into: Path) -> Path:
    """The `pianobot` package as of git revision `ref`, unpacked into `into`."""
    archive = subprocess.run(["git", "-C", str(REPO), "archive", ref, "pianobot"],
                             capture_output=True, check=False)
    if archive.returncode != 0:
        raise SystemExit(f"cannot export {ref!r}: {archive.stderr.decode().strip()}")
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive.stdout, check=True)
    return into


def _with_baseline(result: dict[str, Any], base: dict[str, Any], ref: str) -> dict[str, Any]:
    """The baseline's figures beside the result's, and the ratios of their throughputs."""
    result["baseline"] = {"ref": ref, **{k: base.get(k) for k in (
        "trials_per_s_wall", "trials_per_s_cpu", "raw_simulator_trials_per_s_cpu",
        "raw_simulator_by_lanes_trials_per_s_cpu", "ratio_to_raw_simulator_cpu", "breakdown_cpu_us_per_trial", "peak_rss_mb",
        "bytes_on_disk")}}
    for clock in ("wall", "cpu"):
        result[f"speedup_over_baseline_{clock}"] = round(
            result[f"trials_per_s_{clock}"] / base[f"trials_per_s_{clock}"], 2)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, to check the script")
    parser.add_argument("--large", action="store_true", help="also 100,000 and 1,000,000 trials")
    parser.add_argument("--scenario", choices=SCENARIOS, help=argparse.SUPPRESS)
    parser.add_argument("--only", help="comma-separated scenarios (grid, random, lab_time)")
    parser.add_argument("--baseline", metavar="REF",
                        help="also run grid and random with the pianobot of git revision REF "
                             "(e.g. main), interleaved, and report the speed-up over it")
    parser.add_argument("--random-trials", type=int, default=None,
                        help="trials of the random sweep (default 10,000; 1,000 with --quick)")
    args = parser.parse_args()
    quick = ("--quick",) if args.quick else ()
    random_trials = args.random_trials or (1_000 if args.quick else 10_000)
    if args.scenario is not None:
        runners = {
            "grid": lambda: scenario_grid(args.quick),
            "random": lambda: scenario_random(random_trials),
            "random_large": lambda: scenario_random(100_000),
            "rss_1m": lambda: scenario_random(1_000_000, lean=True),
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
        flags = (*quick, "--random-trials", str(random_trials))
        names = args.only.split(",") if args.only else ["grid", "random", "lab_time"]
        with tempfile.TemporaryDirectory(prefix="pianobot-baseline-") as tmp:
            code = _export(args.baseline, Path(tmp)) if args.baseline else None
            for name in names:
                if code is not None and name in ("grid", "random"):
                    # Interleaved (baseline, this, baseline, this) on a shared machine; the
                    # better run of each is kept, so both get the same chance of a quiet moment.
                    runs = [_child(name, *flags, code=None if k % 2 else code) for k in range(4)]
                    base = max(runs[0::2], key=lambda r: r["trials_per_s_cpu"])
                    this = max(runs[1::2], key=lambda r: r["trials_per_s_cpu"])
                    results[name] = _with_baseline(this, base, args.baseline)
                else:
                    results[name] = _child(name, *flags)
    results["machine"]["load_average_end"] = os.getloadavg()
    text = json.dumps(results, indent=2)
    print(text)
    if not args.quick:
        RESULTS.mkdir(parents=True, exist_ok=True)
        (RESULTS / ("sweep_large.json" if args.large else "sweep.json")).write_text(text + "\n")


if __name__ == "__main__":
    main()
