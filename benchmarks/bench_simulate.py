"""Batch simulator speed and accuracy: `python benchmarks/bench_simulate.py` (prints JSON).

The same 500 one-second keystrokes (random depth, speed and vacuum, seed 0) are simulated
  - with the batch simulator, the study's linear model and with every effect on, at the
    default internal step (0.1 ms) and at the largest allowed one (0.2 ms);
  - with a per-keystroke `scipy.integrate.solve_ivp` baseline of the linear model (RK45,
    rtol 1e-6, atol 1e-9), run on the first `--baseline-n` keystrokes and scaled to 500.
Accuracy is the largest |Δx2| against the same simulator at a 10× finer step, and (linear
model) against the exact state-space solution. Rates are on one core (no threads are used);
the JIT compile happens in a warm-up call and is reported separately. The step cost of the
integrator's 8- and 16-lane blocks against its 4-lane one is measured too (`physics.lanes`: it
depends on the CPU's vector width). The JSON also goes to benchmarks/results/simulate.json.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

from pianobot.physics.effects import Effects  # noqa: E402
from pianobot.physics.lanes import block_costs  # noqa: E402
from pianobot.physics.linear import simulate_linear  # noqa: E402
from pianobot.physics.model import KeystrokeModel  # noqa: E402
from pianobot.physics.msd import MSDParams  # noqa: E402
from pianobot.physics.simulate import SimBatch, simulate_presses  # noqa: E402
from pianobot.physics.trajectory import Press, press_timing, sample_presses  # noqa: E402

N = 500
DURATION_S = 1.0
RESULTS = Path(__file__).resolve().parent / "results" / "simulate.json"


def keystrokes(n: int, seed: int = 0) -> tuple[list[Press], np.ndarray]:
    """One-second presses starting with the fingertip on the key (the study's set-up)."""
    rng = np.random.default_rng(seed)
    presses = [
        Press(0.0, float(rng.uniform(0.02, 0.028)), float(rng.uniform(0.07, 0.08)), 0.08, 1.0, 0.0)
        for _ in range(n)
    ]
    assert all(press_timing(p).t_end_s <= DURATION_S for p in presses)
    return presses, rng.uniform(-80.0, 0.0, n)


def best_rate(fn: Any, n: int, repeats: int = 3) -> tuple[float, float]:
    """(wall-clock, CPU-time) keystrokes per second, best of `repeats`.

    CPU time counts only this process's cycles, so it stays meaningful on a shared machine.
    """
    wall, cpu = math.inf, math.inf
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    return n / wall, n / cpu


def ivp_one(press: Press, vacuum_kpa: float, t_eval: np.ndarray) -> np.ndarray:
    """The linear model of one keystroke with scipy (ramp arm input, coupling engaged)."""
    lp = MSDParams().at(vacuum_kpa)
    tm = press_timing(press, "ramp")
    v_dn, v_up = tm.down.peak_velocity_mps, tm.up.peak_velocity_mps
    t_dn, t_up0, t_end, depth = tm.t_down_end_s, tm.t_hold_end_s, tm.t_end_s, tm.travel_m

    def arm(t: float) -> tuple[float, float]:
        if t < t_dn:
            return v_dn * t, v_dn
        if t < t_up0:
            return depth, 0.0
        if t < t_end:
            return depth - v_up * (t - t_up0), -v_up
        return 0.0, 0.0

    def rhs(t: float, z: np.ndarray) -> list[float]:
        x0, v0 = arm(t)
        x1, v1, x2, v2 = z
        fc = lp.k1_npm * (x1 - x2) + lp.c1_nspm * (v1 - v2)
        a1 = (lp.k0_npm * (x0 - x1) + lp.c0_nspm * (v0 - v1) - fc) / lp.m1_kg
        a2 = (fc - lp.k2_npm * x2 - lp.c2_nspm * v2) / lp.m2_kg
        return [v1, a1, v2, a2]

    sol = solve_ivp(rhs, (0.0, float(t_eval[-1])), [0.0, 0.0, 0.0, 0.0], t_eval=t_eval,
                    rtol=1e-6, atol=1e-9, max_step=0.01)
    return np.asarray(sol.y[2])


def main() -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline-n", type=int, default=25, help="keystrokes run with solve_ivp")
    args = parser.parse_args()
    presses, vacuum = keystrokes(N)
    # Every effect but a yielding body (its own kernel), as measured before that effect existed.
    every = Effects.all().without("finger_hysteresis")
    models = {"linear": KeystrokeModel.study(), "all_effects": KeystrokeModel(effects=every),
              "default_world": KeystrokeModel(effects=Effects.default_world())}

    t0 = time.perf_counter()
    for model in models.values():
        simulate_presses(presses[:2], vacuum[:2], model, duration_s=0.05)
    compile_s = time.perf_counter() - t0

    out: dict[str, Any] = {"keystrokes": N, "duration_s": DURATION_S, "out_dt_s": 1e-3,
                           "jit_warmup_s": round(compile_s, 3), "machine": platform.machine(),
                           "cpu_count": os.cpu_count(), "batch": {}}
    for name, model in models.items():
        for step in (1e-4, 2e-4):
            def run(m: KeystrokeModel = model, h: float = step) -> SimBatch:
                return simulate_presses(presses, vacuum, m, duration_s=DURATION_S, step_s=h)

            rate, cpu_rate = best_rate(run, N)
            coarse = run()
            fine = simulate_presses(presses, vacuum, model, duration_s=DURATION_S, step_s=step / 10)
            entry = {"step_s": step, "keystrokes_per_s": round(rate, 1),
                     "keystrokes_per_cpu_s": round(cpu_rate, 1),
                     "max_abs_dx2_vs_10x_finer_m": float(np.max(np.abs(coarse.x2_m - fine.x2_m)))}
            if name == "linear":
                x0, _ = sample_presses(presses, coarse.t_s, profile="ramp")
                exact = np.vstack([simulate_linear(MSDParams().at(float(p)), coarse.t_s, x0[j])[1]
                                   for j, p in enumerate(vacuum)])
                entry["max_abs_dx2_vs_exact_m"] = float(np.max(np.abs(coarse.x2_m - exact)))
            out["batch"][f"{name}@{step * 1e3:g}ms"] = entry

    # What the 8- and 16-lane blocks cost per step against the 4-lane one on this CPU (what
    # fits group their keystrokes by: physics.lanes), for commanded presses and arm traces.
    out["block_step_costs_vs_4_lanes"] = {
        f"{name}, {'arm trace' if trace else 'commanded'}": block_costs(model, trace=trace)
        for name, model in models.items() for trace in (False, True)}

    t_eval = np.arange(0.0, DURATION_S + 1e-9, 1e-3)
    nb = max(1, min(args.baseline_n, N))
    t0, c0 = time.perf_counter(), time.process_time()
    ivp = np.vstack([ivp_one(presses[j], float(vacuum[j]), t_eval) for j in range(nb)])
    ivp_rate = nb / (time.perf_counter() - t0)
    ivp_cpu_rate = nb / (time.process_time() - c0)
    lin = simulate_presses(presses[:nb], vacuum[:nb], models["linear"], duration_s=DURATION_S)
    out["solve_ivp"] = {"keystrokes_run": nb, "scaled_to": N, "keystrokes_per_s": round(ivp_rate, 2),
                        "keystrokes_per_cpu_s": round(ivp_cpu_rate, 2),
                        "seconds_for_500_scaled": round(N / ivp_rate, 2),
                        "max_abs_dx2_batch_vs_ivp_m": float(np.max(np.abs(lin.x2_m - ivp)))}
    lin_cpu = out["batch"]["linear@0.1ms"]["keystrokes_per_cpu_s"]
    all_cpu = out["batch"]["all_effects@0.1ms"]["keystrokes_per_cpu_s"]
    out["speedup_linear_vs_solve_ivp"] = round(lin_cpu / ivp_cpu_rate, 1)
    # Targets judged on CPU time at the default 0.1 ms step. The default world's Stribeck
    # stick-slip is non-smooth (first-order convergence), so its error is reported, not judged.
    out["targets"] = {
        "linear_keystrokes_per_cpu_s>=20000": lin_cpu >= 20000,
        "all_effects_keystrokes_per_cpu_s>=5000": all_cpu >= 5000,
        "speedup>=100": out["speedup_linear_vs_solve_ivp"] >= 100,
        "error<=5um": all(e["max_abs_dx2_vs_10x_finer_m"] <= 5e-6 for k, e in out["batch"].items()
                          if not k.startswith("default_world")),
    }
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(out, indent=2))
    return out


if __name__ == "__main__":
    main()
