"""Benchmark the independent truth generators (tests/truth): suite generation time and the
integrator's long steps against short steps only (the obvious baseline), in the same run.

    .venv/bin/python benchmarks/bench_truth.py [--only TEXT ...] [--no-suite] [--out FILE]

Writes JSON to benchmarks/results/truth.json (and a summary to stdout): seconds per scenario
(mocap takes of 24 keystrokes, MIDI-only logs of 135, both including the second simulation that
measures the effect's size) and whether pianobot's importer reads each file back as the session it
is (every press / every keystroke's on-velocity), and for a clean shallow take, a clean deep take and a clean log the
integrator's time with long steps vs with the 20.8 µs step throughout, the ratio, and the largest
difference between the two trajectories.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.truth import full_suite, materialise, scenario  # noqa: E402
from tests.truth.base import BASE_SETS  # noqa: E402
from tests.truth.plant import Plant  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results" / "truth.json"


def _take_presses(name: str) -> tuple[Plant, list[Any], float]:
    s = scenario(name)
    from tests.truth.materialise import simulate_take

    presses, _ = simulate_take(s)  # also warms the compiled kernel
    plant = Plant(BASE_SETS[s.base], s.vacuum_kpa, s.take.distance_m)
    moves = [m for p in presses for m in p.moves()]
    return plant, moves, presses[-1].t_end_s + s.take.tail_s


def step_ratio() -> list[dict[str, Any]]:
    """Long steps vs short steps only, on clean sessions (seconds, ratio, max |Δx| in metres)."""
    rows = []
    for name in ("mocap-clean-light-finger-shallow-0", "mocap-clean-light-finger-deep-1"):
        plant, moves, t_end = _take_presses(name)
        timing, traj = {}, {}
        for coarse in (1, 20):
            t0 = time.perf_counter()
            traj[coarse] = plant.simulate(moves, t_end, coarse=coarse)
            timing[coarse] = time.perf_counter() - t0
        diff = max(float(np.max(np.abs(traj[1][k] - traj[20][k]))) for k in ("x1_m", "x2_m"))
        rows.append({"session": name, "short_steps_s": timing[1], "long_steps_s": timing[20],
                     "speedup": timing[1] / timing[20], "max_difference_m": diff})  # fmt: skip
    s = scenario("midi-clean-light-finger-0")
    plant = Plant(BASE_SETS[s.base], s.vacuum_kpa, s.grid.distance_m)
    timing, keys = {}, {}
    for coarse in (1, 20):
        t0 = time.perf_counter()
        keys[coarse] = []
        for press in s.grid.presses():
            traj = plant.simulate(press.moves(), press.t_end_s + 0.6, record_every=4, coarse=coarse)
            keys[coarse].append(traj["x2_m"])
        timing[coarse] = time.perf_counter() - t0
    diff = max(float(np.max(np.abs(a - b))) for a, b in zip(keys[1], keys[20], strict=True))
    rows.append({"session": s.name, "short_steps_s": timing[1], "long_steps_s": timing[20],
                 "speedup": timing[1] / timing[20], "max_difference_m": diff})  # fmt: skip
    return rows


def imports_cleanly(made: Any, data_dir: Path) -> bool:
    """Whether pianobot's importer reads the file as the lab session it is: every press of a
    take segmented, every keystroke of a log with the on-velocity the piano sent."""
    from pianobot.io.importers import import_keystroke_log, import_mocap
    from pianobot.store import load_run

    if made.scenario.kind == "mocap":
        result = import_mocap(made.files["take"], data_dir, vacuum_kpa=made.scenario.vacuum_kpa)
        return result.trials == len(made.truth["presses"])
    result = import_keystroke_log(made.files["log"], data_dir)
    trials = load_run(result.run_id, data_dir).trials.sort_values("index")
    want = [np.nan if r["on_velocity"] is None else r["on_velocity"] for r in made.truth["strokes"]]
    return result.trials == len(want) and bool(
        np.array_equal(trials["on_velocity"].to_numpy(), np.array(want, float), equal_nan=True)
    )


def suite_timing(only: list[str]) -> list[dict[str, Any]]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for s in full_suite():
            if only and not any(text in s.name for text in only):
                continue
            t0 = time.perf_counter()
            made = materialise(s, tmp)
            seconds = time.perf_counter() - t0
            ok = imports_cleanly(made, Path(tmp) / "data")
            rows.append({"scenario": s.name, "kind": s.kind, "strength": s.strength,
                         "seconds": seconds, "imports": ok,
                         "effect_size": made.truth.get("effect_size"),
                         "unresolved_steps": made.truth["outcome"]["unresolved_steps"]})  # fmt: skip
            print(f"{s.name:48s} {seconds:6.2f} s  import {'ok' if ok else 'MISMATCH'}", flush=True)
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", action="append", default=[], metavar="TEXT")
    parser.add_argument("--no-suite", action="store_true", help="only the step-ratio part")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    ratio = step_ratio()
    for row in ratio:
        print(f"{row['session']:48s} short {row['short_steps_s']:6.2f} s  long "
              f"{row['long_steps_s']:6.2f} s  x{row['speedup']:.1f}  "
              f"max |dx| {row['max_difference_m'] * 1e9:.1f} nm")  # fmt: skip
    suite = [] if args.no_suite else suite_timing(args.only)
    summary: dict[str, Any] = {}
    for kind in ("mocap", "midi"):
        times = [r["seconds"] for r in suite if r["kind"] == kind]
        if times:
            summary[kind] = {"scenarios": len(times), "median_s": float(np.median(times)),
                             "max_s": float(np.max(times)), "total_s": float(np.sum(times)),
                             "import_ok": sum(r["imports"] for r in suite if r["kind"] == kind)}  # fmt: skip
    result = {"step_ratio": ratio, "suite": suite, "summary": summary}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
