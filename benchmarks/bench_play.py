"""Benchmark `play`: how well and how fast each test song is played, and what planning costs.

Per test song (`pianobot.play.library.TEST_SONGS`, built in code) and finger (soft on the
built-in sim rig; rigid on `experiments/rigs/sim-rigid.yaml`), seeded:

- `model`: the default command (warm-up on, tempo auto, no --adapt);
- `naive`: the study's demo logic, at the tempo the model chose (same tempo: the comparison
  measures the model, not the tempo) and at the written tempo;
- `adapt`: the default command with --adapt;
- F1 (mir_eval, 50 ms, on the clock of the tempo played), onset RMS, velocity MAE (mapped), the
  tempo played, the fastest tempo the finger can physically sustain (a brute-force search on the
  simulated world's truth, `tests/play/play_reference.py`) and the ratio of the two, the warm-up's
  lab time.

Planning: time per note to plan etudes of 1,000, 5,000 and 20,000 notes with the published
model (tables, the feasible tempo, the schedule; with and without the choice among geometries),
against the baseline a planner without tables pays per note (the model's own inverse, asked per
note), measured in the same run.

    .venv/bin/python benchmarks/bench_play.py [--songs ode,march] [--out FILE]
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

from pianobot.analysis.predictors import PhysicsPredictor
from pianobot.io.midifile import write_song
from pianobot.physics.world import World, WorldConfig
from pianobot.play import PlayResult, PlaySettings, play_rig, play_song
from pianobot.play.geometry import fastest_geometry
from pianobot.play.library import TEST_SONGS, etude
from pianobot.play.plan import plan_model
from pianobot.play.strokes import stroke_tables

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "play.json"
RIGID_RIG = HERE.parent / "experiments" / "rigs" / "sim-rigid.yaml"
sys.path.insert(0, str(HERE.parent / "tests" / "play"))
from play_reference import fastest_sustainable_bpm, strokes, truth_table  # noqa: E402

FINGERS = {"soft": "sim", "rigid": str(RIGID_RIG)}


def _truth(finger: str) -> list[Any]:
    """The world's truth tables for the reference tempo (every level, every stroke shape)."""
    settings = PlaySettings(finger=finger)  # type: ignore[arg-type]
    rig = play_rig(FINGERS[finger])
    world = World(WorldConfig.model_validate({k: v for k, v in rig.world.items() if k != "preset"}), 0)
    envelope = rig.envelope_for(finger)  # type: ignore[arg-type]
    presses = strokes(settings.play_depth_m, np.geomspace(0.008, envelope["down_velocity_mps"].high, 28))
    levels = [p for p in settings.levels_kpa if envelope["vacuum_kpa"].contains(p)]
    return [truth_table(world, level, presses) for level in levels]


def _row(result: PlayResult) -> dict[str, Any]:
    score, tempo = result.score, result.plan.tempo
    assert score is not None and tempo is not None
    return {"f1": score.f1, "onset_rms_ms": score.onset_rms_ms, "velocity_mae": score.velocity_mae,
            "tempo_bpm": tempo.played_bpm, "skipped": int((result.plan.notes["status"] == "skip").sum()),
            "f1_beat": score.f1_beat, "warmup_lab_time_s": None if result.warmup is None else result.warmup.lab_time_s}


def _songs(names: list[str], data: Path) -> dict[str, list[dict[str, Any]]]:
    out: dict[str, list[dict[str, Any]]] = {}
    for finger, rig in FINGERS.items():
        truth = _truth(finger)
        rows = []
        for name in names:
            spec = TEST_SONGS[name]()
            path = write_song(data / f"{name}.mid", spec.to_notes(), tempo_bpm=spec.tempo_bpm)
            common = {"data_dir": data, "rig": rig, "finger": finger, "seed": 0}
            model = play_song(path, **common)  # type: ignore[arg-type]
            assert model.plan.tempo is not None
            played = str(model.plan.tempo.played_bpm)
            naive = play_song(path, planner="naive", tempo=played, **common)  # type: ignore[arg-type]
            naive_written = play_song(path, planner="naive", tempo="written", **common)  # type: ignore[arg-type]
            adapt = play_song(path, adapt=True, **common)  # type: ignore[arg-type]
            reference = fastest_sustainable_bpm(list(model.melody.notes), spec.tempo_bpm, truth, play_rig(rig))
            row = {"song": name, "written_bpm": spec.tempo_bpm, "notes": len(model.melody.notes),
                   "reference_bpm": reference.bpm,
                   "tempo_over_reference": model.plan.tempo.played_bpm / reference.bpm,
                   "model": _row(model), "naive_same_tempo": _row(naive), "naive_written": _row(naive_written),
                   "adapt": _row(adapt)}
            rows.append(row)
            print(f"{finger} {name}: model F1 {row['model']['f1']:.3f} onset {row['model']['onset_rms_ms']:.1f} ms "
                  f"MAE {row['model']['velocity_mae']:.2f} at {row['model']['tempo_bpm']:g} bpm "
                  f"(reference {reference.bpm:g}); naive F1 {row['naive_same_tempo']['f1']:.3f}; "
                  f"adapt F1 {row['adapt']['f1']:.3f}", file=sys.stderr)
        out[finger] = rows
    return out


def _planning(sizes: list[int]) -> list[dict[str, Any]]:
    predictor = PhysicsPredictor.published()
    settings, rig = PlaySettings(), play_rig("sim")
    geometry = fastest_geometry(settings, rig)
    rows = []
    for n in sizes:
        notes = etude(n).to_notes()
        t0 = time.perf_counter()
        tables = stroke_tables(predictor, settings, rig, geometry)
        tabulate_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        plan = plan_model(notes, predictor, settings, rig, tables=tables, written_bpm=90.0)
        plan_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        plan_model(notes, predictor, settings, rig, written_bpm=90.0)  # every candidate geometry
        choose_s = time.perf_counter() - t0
        table = tables[float(plan.notes["vacuum_kpa"].iloc[0])]
        sample = plan.notes["target_velocity"].to_numpy(float)[:50]
        t0 = time.perf_counter()
        for target in sample:
            predictor.inverse(np.array([target]), vacuum_kpa=table.vacuum_kpa, acceleration_mps2=geometry.acceleration_mps2,
                              depth_m=geometry.depth_m, distance_m=geometry.distance_m)
        direct_ms = (time.perf_counter() - t0) / sample.size * 1e3
        per_note_ms = plan_s / n * 1e3
        rows.append({"notes": n, "tabulate_s": tabulate_s, "plan_s": plan_s, "per_note_plan_ms": per_note_ms,
                     "plan_choosing_geometry_s": choose_s, "per_note_choosing_geometry_ms": choose_s / n * 1e3,
                     "baseline_per_note_direct_inverse_ms": direct_ms,
                     "baseline_over_plan_per_note": direct_ms / per_note_ms,
                     "tempo_bpm": plan.tempo.played_bpm if plan.tempo else None})
        print(f"plan {n} notes: {per_note_ms * 1e3:.0f} µs/note ({choose_s / n * 1e6:.0f} µs with the geometry "
              f"choice); direct inverse {direct_ms:.2f} ms/note", file=sys.stderr)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--songs", default=",".join(TEST_SONGS))
    parser.add_argument("--sizes", default="1000,5000,20000")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        songs = _songs([s for s in args.songs.split(",") if s], Path(tmp))
    result = {"songs": songs, "planning": _planning([int(s) for s in args.sizes.split(",")])}
    text = json.dumps(result, indent=2)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text + "\n", encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
