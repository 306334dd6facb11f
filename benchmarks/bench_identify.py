"""Identification benchmark: recovery and interval coverage over 20 seeded sweeps (JSON out).

Each repetition runs a small sweep of the simulated world's linear preset with known parameters
(the study's model plus mocap and arm-log noise) through the real runner and store — two vacuum
levels, two speeds, two depths, two repeats: 16 keystrokes with the fingertip starting
`--distance-m` above the key, as in the lab's sweeps — then identifies the model from the stored
run (Jacobian + optional keystroke-bootstrap intervals) and records the relative errors, whether
each 95 % interval covers the truth, and the wall time of the fit.

    .venv/bin/python benchmarks/bench_identify.py [--reps 20] [--bootstrap 0] [--distance-m 0.05]
        [--x0-source auto|sim-truth] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "analysis"))
from _synthetic_runs import linear_sweep  # noqa: E402

from pianobot.analysis.greybox.load import load_batch  # noqa: E402
from pianobot.analysis.identify.fit import identify_trajectories  # noqa: E402
from pianobot.physics.msd import MSDParams  # noqa: E402

TRUTH = MSDParams(k1_a_npm=70.0, k1_b_npm_per_kpa=1.4, c1_nspm=0.45, k2_npm=330.0, c2_nspm=0.33)


def truth_of(name: str) -> float:
    match = re.fullmatch(r"k1_npm@(-?[\d.]+)kPa", name)
    if match:
        return TRUTH.k1_npm(float(match.group(1)))
    return {"c1_nspm": TRUTH.c1_nspm, "k2_npm": TRUTH.k2_npm, "c2_nspm": TRUTH.c2_nspm,
            "c1_over_m1_per_s": TRUTH.c1_nspm / TRUTH.m1_kg, "c2_over_m2_per_s": TRUTH.c2_nspm / TRUTH.m2_kg,
            "k2_over_m2_per_s2": TRUTH.k2_npm / TRUTH.m2_kg, "k1_a_npm": TRUTH.k1_a_npm,
            "k1_b_npm_per_kpa": TRUTH.k1_b_npm_per_kpa}.get(name, math.nan)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--reps", type=int, default=20)
    parser.add_argument("--bootstrap", type=int, default=0)
    parser.add_argument("--distance-m", type=float, default=0.05)
    parser.add_argument("--x0-source", default="auto", help="arm (the 500 Hz log; auto) or sim-truth")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    per_param: dict[str, dict[str, list[float]]] = {}
    times = []
    n_keystrokes = 0
    with tempfile.TemporaryDirectory() as scratch:
        for seed in range(args.reps):
            data = Path(scratch) / f"rep{seed}" / "data"
            data.mkdir(parents=True)
            run = linear_sweep(data, seed=1000 + seed, truth=TRUTH, distance_m=args.distance_m)
            batch, _ = load_batch([run], data, x0_source=args.x0_source)
            n_keystrokes = batch.n
            t0 = time.perf_counter()
            fit = identify_trajectories(batch, coupling="tied", bootstrap=args.bootstrap, seed=seed)
            times.append(time.perf_counter() - t0)
            for e in fit.estimates:
                truth = truth_of(e.name)
                if math.isnan(truth):
                    continue
                rec = per_param.setdefault(e.name, {"rel_error": [], "covered": [], "covered_jacobian": [],
                                                    "covered_bootstrap": []})
                rec["rel_error"].append(abs(e.value - truth) / abs(truth))
                lo, hi = e.ci95
                rec["covered"].append(float(lo <= truth <= hi))
                rec["covered_jacobian"].append(float(e.ci_jacobian[0] <= truth <= e.ci_jacobian[1]))
                if e.ci_bootstrap is not None:
                    rec["covered_bootstrap"].append(float(e.ci_bootstrap[0] <= truth <= e.ci_bootstrap[1]))
    summary = {
        name: {"max_rel_error": max(r["rel_error"]), "coverage": sum(r["covered"]) / len(r["covered"])}
        for name, r in per_param.items()
    }

    def overall(key: str) -> float | None:
        values = [c for r in per_param.values() for c in r[key]]
        return sum(values) / len(values) if values else None

    payload = {"reps": args.reps, "bootstrap": args.bootstrap, "data": "sim sweep, world preset linear",
               "distance_m": args.distance_m, "x0_source": args.x0_source, "keystrokes_per_rep": n_keystrokes, "params": summary,
               "coverage_overall": overall("covered"),
               "coverage_jacobian_hac": overall("covered_jacobian"),
               "coverage_bootstrap": overall("covered_bootstrap"),
               "seconds_per_fit_median": sorted(times)[len(times) // 2]}
    text = json.dumps(payload, indent=2)
    if args.out:
        args.out.write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
