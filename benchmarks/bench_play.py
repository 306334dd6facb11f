"""Benchmark `play`: how well and how fast each test song is played, and what planning costs.

Per test song (`pianobot.play.library.TEST_SONGS`, built in code) and setting — the soft
finger on the built-in sim rig, the rigid finger on `experiments/rigs/sim-rigid.yaml`, and the
soft finger on a piano simulated by the independent truth lab (`tests/truth`, base set
`stiff-key`, through `tests/play/truth_world.py`) — seeded:

- `model`: the default command (warm-up on, tempo auto, no --adapt);
- `naive`: the study's demo logic, at the tempo the model chose (same tempo: the comparison
  measures the model, not the tempo) and at the written tempo;
- `adapt`: the default command with --adapt;
- F1 (mir_eval, 50 ms, on the clock of the tempo played), onset RMS, velocity MAE (mapped), the
  tempo played, the fastest tempo the finger can physically sustain (a brute-force search on the
  simulated world's truth, `tests/play/play_reference.py`) and the ratio of the two, the warm-up's
  lab time.

Planning: time per note to plan etudes of 1,000, 5,000 and 20,000 notes with the published
model (the feasible tempo and the schedule with the stroke tables given; and everything,
tabulating every candidate geometry), against the baseline measured in the same run: the naive
planner (the study's demo logic: a linear speed map and one pass), the least any planner does.

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
from pianobot.play.naive import plan_naive
from pianobot.play.plan import plan_model
from pianobot.play.strokes import stroke_tables

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "play.json"
RIGID_RIG = HERE.parent / "experiments" / "rigs" / "sim-rigid.yaml"
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE.parent / "tests" / "play"))
from play_reference import fastest_sustainable_bpm, strokes, truth_table  # noqa: E402
from truth_world import TruthWorld  # noqa: E402

# setting → (finger, rig, world: None for the rig's own)
SETTINGS: dict[str, tuple[str, str, Any]] = {
    "soft": ("soft", "sim", None),
    "rigid": ("rigid", str(RIGID_RIG), None),
    "soft-truth-lab": ("soft", "sim", "stiff-key"),
}


def _world(setting: str) -> Any:
    finger, rig_name, base = SETTINGS[setting]
    if base is not None:
        return TruthWorld(base)
    rig = play_rig(rig_name)
    return World(WorldConfig.model_validate({k: v for k, v in rig.world.items() if k != "preset"}), 0)


def _truth(setting: str) -> list[Any]:
    """The world's truth tables for the reference tempo (every level, every stroke shape)."""
    finger, rig_name, _ = SETTINGS[setting]
    settings = PlaySettings(finger=finger)  # type: ignore[arg-type]
    envelope = play_rig(rig_name).envelope_for(finger)  # type: ignore[arg-type]
    presses = strokes(settings.play_depth_m, np.geomspace(0.008, envelope["down_velocity_mps"].high, 28))
    levels = [p for p in settings.levels_kpa if envelope["vacuum_kpa"].contains(p)]
    world = _world(setting)
    return [truth_table(world, level, presses) for level in levels]


def _row(result: PlayResult) -> dict[str, Any]:
    score, tempo = result.score, result.plan.tempo
    assert score is not None and tempo is not None
    return {"f1": score.f1, "onset_rms_ms": score.onset_rms_ms, "velocity_mae": score.velocity_mae,
            "tempo_bpm": tempo.played_bpm, "skipped": int((result.plan.notes["status"] == "skip").sum()),
            "f1_beat": score.f1_beat, "warmup_lab_time_s": None if result.warmup is None else result.warmup.lab_time_s}


def _songs(names: list[str], settings: list[str], data: Path) -> dict[str, list[dict[str, Any]]]:
    out: dict[str, list[dict[str, Any]]] = {}
    for setting in settings:
        finger, rig, _ = SETTINGS[setting]
        truth = _truth(setting)
        rows = []
        for name in names:
            spec = TEST_SONGS[name]()
            path = write_song(data / f"{name}.mid", spec.to_notes(), tempo_bpm=spec.tempo_bpm)

            def play(**options: Any) -> PlayResult:
                return play_song(path, data_dir=data, rig=rig, finger=finger, seed=0,  # noqa: B023
                                 world=None if SETTINGS[setting][2] is None else _world(setting), **options)  # noqa: B023

            model = play()
            assert model.plan.tempo is not None
            naive = play(planner="naive", tempo=str(model.plan.tempo.played_bpm))
            naive_written = play(planner="naive", tempo="written")
            adapt = play(adapt=True)
            reference = fastest_sustainable_bpm(list(model.melody.notes), spec.tempo_bpm, truth, play_rig(rig))
            row = {"song": name, "written_bpm": spec.tempo_bpm, "notes": len(model.melody.notes),
                   "reference_bpm": reference.bpm,
                   "tempo_over_reference": model.plan.tempo.played_bpm / reference.bpm,
                   "dry_run_feasible_bpm": None if model.prior_plan is None or model.prior_plan.tempo is None
                   else model.prior_plan.tempo.feasible_bpm,
                   "model": _row(model), "naive_same_tempo": _row(naive), "naive_written": _row(naive_written),
                   "adapt": _row(adapt)}
            rows.append(row)
            print(f"{setting} {name}: model F1 {row['model']['f1']:.3f} onset {row['model']['onset_rms_ms']:.1f} ms "
                  f"MAE {row['model']['velocity_mae']:.2f} at {row['model']['tempo_bpm']:g} bpm "
                  f"(reference {reference.bpm:.1f}); naive F1 {row['naive_same_tempo']['f1']:.3f}; "
                  f"adapt F1 {row['adapt']['f1']:.3f}", file=sys.stderr)
        out[setting] = rows
    return out


def _planning(sizes: list[int]) -> list[dict[str, Any]]:
    predictor = PhysicsPredictor.published()
    settings, rig = PlaySettings(), play_rig("sim")
    tables = stroke_tables(predictor, settings, rig, fastest_geometry(settings, rig))
    rows = []
    for n in sizes:
        notes = etude(n).to_notes()
        t0 = time.perf_counter()
        plan = plan_model(notes, predictor, settings, rig, tables=tables, written_bpm=90.0)
        plan_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        plan_model(notes, predictor, settings, rig, written_bpm=90.0)  # tabulating every candidate geometry
        full_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        plan_naive(notes, settings, rig, written_bpm=90.0)
        naive_s = time.perf_counter() - t0
        rows.append({"notes": n, "per_note_plan_ms": plan_s / n * 1e3, "per_note_plan_with_tabulation_ms": full_s / n * 1e3,
                     "per_note_naive_ms": naive_s / n * 1e3, "plan_over_naive": plan_s / naive_s,
                     "tempo_bpm": plan.tempo.played_bpm if plan.tempo else None})
        print(f"plan {n} notes: {plan_s / n * 1e6:.0f} µs/note ({full_s / n * 1e6:.0f} µs tabulating every geometry); "
              f"naive {naive_s / n * 1e6:.0f} µs/note: {plan_s / naive_s:.1f}x", file=sys.stderr)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--songs", default=",".join(TEST_SONGS))
    parser.add_argument("--settings", default=",".join(SETTINGS))
    parser.add_argument("--sizes", default="1000,5000,20000")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        songs = _songs([s for s in args.songs.split(",") if s], [s for s in args.settings.split(",") if s], Path(tmp))
    result = {"songs": songs, "planning": _planning([int(s) for s in args.sizes.split(",")])}
    text = json.dumps(result, indent=2)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text + "\n", encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
