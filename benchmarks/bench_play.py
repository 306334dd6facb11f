"""Benchmark the `play` planner: a 1,000-note song, per-note inverse time, physics vs GP model.

For each model: the time to tabulate it over the play stroke configuration (one table per
vacuum level), the time to plan a 1,000-note song (mapping, inverse, timing, scheduling) with
one geometry and with the choice among every candidate geometry (tables included), the
per-note inverse through the table, and the per-note inverse asked of the model directly
(`StrokePredictor.inverse`, what a planner without tables would pay), and the online adapter's
work per note over the whole song (`--adapt`: two forecasts over the feasibility grid, the
choice, the update; the played loudness is the model's × 1.3, rounded). The GP is learned from the
calibration sweep on the default sim world. Writes JSON to benchmarks/results/play.json (and
stdout).

    .venv/bin/python benchmarks/bench_play.py [--notes 1000] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from pianobot.analysis.learn.predictors import PhysicsPredictor, StrokePredictor
from pianobot.analysis.learn.training import LearnedPredictor, training_set
from pianobot.play.adapt import OnlineAdapter
from pianobot.play.library import etude
from pianobot.play.perform import FEASIBILITY_GRID
from pianobot.play.plan import fastest_geometry, geometries, plan_model, stroke_tables
from pianobot.play.session import play_rig
from pianobot.play.settings import PlaySettings
from pianobot.run import run_sweep
from pianobot.store import load_run

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "play.json"
CALIBRATION = HERE.parent / "experiments" / "play_calibration.yaml"
PLAY_RIG = HERE.parent / "experiments" / "rigs" / "sim-play.yaml"


def _gp() -> LearnedPredictor:
    with tempfile.TemporaryDirectory() as tmp:
        outcome = run_sweep(CALIBRATION, data_dir=Path(tmp), progress=False)
        trials = load_run(outcome.run_id, Path(tmp)).trials
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return LearnedPredictor("gp").fit(training_set(trials))


def _measure(predictor: StrokePredictor, n_notes: int) -> dict[str, Any]:
    settings = PlaySettings()
    rig = play_rig(PLAY_RIG)
    notes = etude(n_notes).to_notes()
    geometry = fastest_geometry(settings, rig)
    t0 = time.perf_counter()
    tables = stroke_tables(predictor, settings, rig, geometry)
    table_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    plan = plan_model(notes, predictor, settings, rig, tables=tables)
    plan_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    chosen = plan_model(notes, predictor, settings, rig)  # every candidate geometry, best kept
    choose_s = time.perf_counter() - t0
    targets = plan.notes["target_velocity"].to_numpy(float)
    table = tables[float(plan.notes["vacuum_kpa"].iloc[0])]
    t0 = time.perf_counter()
    for target in targets:
        table.inverse(target)
    per_note_table_us = (time.perf_counter() - t0) / targets.size * 1e6
    direct = targets[: min(50, targets.size)]
    t0 = time.perf_counter()
    for target in direct:
        predictor.inverse(np.array([target]), vacuum_kpa=table.vacuum_kpa, acceleration_mps2=geometry.acceleration_mps2,
                          depth_m=geometry.depth_m, distance_m=geometry.distance_m)
    per_note_direct_ms = (time.perf_counter() - t0) / direct.size * 1e3
    adapter = OnlineAdapter()
    grid = np.linspace(table.speeds_mps[0], table.speeds_mps[-1], FEASIBILITY_GRID)
    model_velocity, model_lead = table.predict_velocity(grid), table.lead(grid)
    t0 = time.perf_counter()
    for i, target in enumerate(targets):
        forecast = adapter.forecast(table.vacuum_kpa, grid, model_velocity, model_lead)
        adapter.forecast(table.vacuum_kpa, grid, model_velocity, model_lead)  # the look-ahead
        k = adapter.choose(forecast, float(target))
        adapter.observe(i, table.vacuum_kpa, float(grid[k]), float(model_velocity[k]), float(model_lead[k]),
                        round(1.3 * float(model_velocity[k])), float(model_lead[k]))
    per_note_adapt_ms = (time.perf_counter() - t0) / targets.size * 1e3
    return {
        "notes": n_notes,
        "tabulate_s": table_s,
        "plan_s": plan_s,
        "plan_total_s": table_s + plan_s,
        "plan_choosing_geometry_s": choose_s,
        "candidate_geometries": len(geometries(settings, rig)),
        "chosen_hover_m": chosen.geometry.distance_m if chosen.geometry else None,
        "per_note_plan_ms": plan_s / n_notes * 1e3,
        "per_note_inverse_table_us": per_note_table_us,
        "per_note_inverse_direct_ms": per_note_direct_ms,
        "per_note_adapt_ms": per_note_adapt_ms,
        "planned": int((plan.notes["status"] == "play").sum()),
        "reachable": list(plan.dynamics.target_range) if plan.dynamics else None,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--notes", type=int, default=1000)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    t0 = time.perf_counter()
    gp = _gp()
    gp_fit_s = time.perf_counter() - t0
    result = {
        "physics_published": _measure(PhysicsPredictor.published(), args.notes),
        "gp_from_sim_sweep": {**_measure(gp, args.notes), "fit_s_including_sweep": gp_fit_s},
    }
    physics, gp_row = result["physics_published"], result["gp_from_sim_sweep"]
    result["gp_over_physics_plan_total"] = gp_row["plan_total_s"] / physics["plan_total_s"]
    text = json.dumps(result, indent=2)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text + "\n", encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
