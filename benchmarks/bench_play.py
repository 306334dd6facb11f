"""Benchmark `play`: how well and how fast each test song is played, and what planning costs.

Per song — the test songs (`pianobot.play.library.TEST_SONGS`, built in code), the repo's
`experiments/songs/*.mid` and `held_out`, a song written here and never used by tests or
tuning (thirty notes at 100 bpm: repeated notes, a dotted rhythm, loudness 40 → 88 → 40, the
shape of the melody the play issue was measured on) — and setting — the soft
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
  lab time;
- the default against naive at the written tempo (what `--planner naive` does with no other
  option) as ratios: F1 model/naive, onset RMS and velocity MAE naive/model (a ratio of a
  zero or undefined score is null), and the notes each played, skipped and missed.

Planning: time per note to plan etudes of 1,000, 5,000 and 20,000 notes with the published
model (the feasible tempo and the schedule with the stroke tables given; and everything,
tabulating every candidate geometry), against the baseline measured in the same run: the naive
planner (the study's demo logic: a linear speed map and one pass), the least any planner does.

    .venv/bin/python benchmarks/bench_play.py [--songs ode,held_out,twinkle] [--settings soft] [--no-adapt] [--out FILE]
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

from pianobot.analysis.learn.physical import PhysicsPredictor
from pianobot.io.midifile import read_song, write_song
from pianobot.physics.world import World, WorldConfig
from pianobot.play import PlayResult, PlaySettings, play_rig, play_song
from pianobot.play.geometry import fastest_geometry
from pianobot.play.library import PP, TEST_SONGS, SongSpec, etude
from pianobot.play.naive import plan_naive
from pianobot.play.song_plan import plan_model
from pianobot.play.strokes import stroke_tables

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "play.json"
RIGID_RIG = HERE.parent / "experiments" / "rigs" / "sim-rigid.yaml"
SONG_FILES = HERE.parent / "experiments" / "songs"
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


def held_out() -> SongSpec:
    """Thirty notes at 100 bpm in D major, written for this benchmark only: repeated notes, a
    dotted figure, a fifth and an octave leap, loudness 40 → 88 → 40 in uneven steps."""
    d4, e4, fs4, g4, a4, b4, cs5, d5 = 62, 64, 66, 67, 69, 71, 73, 74
    pitches = [d4, d4, a4, a4, b4, b4, a4, g4, g4, fs4, fs4, e4, e4, d4, a4,
               d5, d5, cs5, b4, a4, a4, b4, g4, fs4, e4, e4, fs4, d4, d4, d5]
    beats = [1.0] * 6 + [2.0] + [1.0] * 3 + [1.5, 0.5, 1.0, 2.0, 1.0] + [1.0] * 4 + [1.5, 0.5] + [1.0] * 5 + [1.5, 0.5, 2.0, 2.0]
    velocities = [40, 42, 46, 50, 52, 58, 60, 64, 66, 70, 72, 76, 80, 84, 88,
                  88, 86, 80, 78, 72, 70, 64, 60, 56, 52, 50, 46, 44, 42, 40]
    assert len(pitches) == len(beats) == len(velocities) == 30 and min(velocities) > PP
    return SongSpec("held_out", 100.0, tuple(zip(pitches, beats, velocities, strict=True)))


def _song_paths(names: list[str], data: Path) -> dict[str, tuple[Path, float]]:
    """Each song as a MIDI file and its written tempo (quarter notes/min)."""
    out = {}
    for name in names:
        if name in TEST_SONGS or name == "held_out":
            spec = held_out() if name == "held_out" else TEST_SONGS[name]()
            out[name] = (write_song(data / f"{name}.mid", spec.to_notes(), tempo_bpm=spec.tempo_bpm), spec.tempo_bpm)
        else:
            path = SONG_FILES / f"{name}.mid"
            out[name] = (path, read_song(path).tempo_bpm)
    return out


def _ratio(num: float, den: float) -> float | None:
    return float(num / den) if np.isfinite(num) and np.isfinite(den) and den > 0 and num > 0 else None


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
    skipped = int((result.plan.notes["status"] == "skip").sum())
    return {"f1": score.f1, "onset_rms_ms": score.onset_rms_ms, "velocity_mae": score.velocity_mae,
            "tempo_bpm": tempo.played_bpm, "skipped": skipped, "notes": score.notes_target,
            "played": score.notes_played, "missed": score.notes_target - score.notes_paired - skipped,
            "note_status": score.to_dict()["note_status"],
            "f1_beat": score.f1_beat, "warmup_lab_time_s": None if result.warmup is None else result.warmup.lab_time_s}


def _songs(names: list[str], settings: list[str], data: Path, adapt: bool = True) -> dict[str, list[dict[str, Any]]]:
    out: dict[str, list[dict[str, Any]]] = {}
    paths = _song_paths(names, data)
    for setting in settings:
        finger, rig, _ = SETTINGS[setting]
        truth = _truth(setting)
        rows = []
        for name, (path, written_bpm) in paths.items():

            def play(**options: Any) -> PlayResult:
                return play_song(path, data_dir=data, rig=rig, finger=finger, seed=0,  # noqa: B023
                                 world=None if SETTINGS[setting][2] is None else _world(setting), **options)  # noqa: B023

            t0 = time.process_time()
            model = play()
            model_cpu_s = time.process_time() - t0
            assert model.plan.tempo is not None
            naive = play(planner="naive", tempo=str(model.plan.tempo.played_bpm))
            naive_written = play(planner="naive", tempo="written")
            reference = fastest_sustainable_bpm(list(model.melody.notes), written_bpm, truth, play_rig(rig))
            m, n = _row(model), _row(naive_written)
            row = {"song": name, "written_bpm": written_bpm, "notes": len(model.melody.notes),
                   "reference_bpm": reference.bpm,
                   "tempo_over_reference": model.plan.tempo.played_bpm / reference.bpm,
                   "dry_run_feasible_bpm": None if model.prior_plan is None or model.prior_plan.tempo is None
                   else model.prior_plan.tempo.feasible_bpm,
                   "tempo_line": next((w for w in model.warnings if "too fast" in w), None),
                   "model": m, "naive_same_tempo": _row(naive), "naive_written": n,
                   "adapt": _row(play(adapt=True)) if adapt else None,
                   "model_over_naive_written": {"f1": _ratio(m["f1"], n["f1"]),
                                                "onset_rms_naive_over_model": _ratio(n["onset_rms_ms"], m["onset_rms_ms"]),
                                                "velocity_mae_naive_over_model": _ratio(n["velocity_mae"], m["velocity_mae"])},
                   "model_cpu_s": model_cpu_s}
            rows.append(row)
            print(f"{setting} {name}: model F1 {m['f1']:.3f} onset {m['onset_rms_ms']:.1f} ms "
                  f"MAE {m['velocity_mae']:.2f} skipped {m['skipped']} at {m['tempo_bpm']:.4g} bpm "
                  f"(written {written_bpm:g}, reference {reference.bpm:.1f}); naive at written: F1 {n['f1']:.3f} "
                  f"onset {n['onset_rms_ms']:.1f} ms MAE {n['velocity_mae']:.2f} missed {n['missed']}; "
                  f"naive same tempo F1 {row['naive_same_tempo']['f1']:.3f}"
                  + (f"; adapt F1 {row['adapt']['f1']:.3f}" if adapt else ""), file=sys.stderr)
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
    parser.add_argument("--songs", default=",".join([*TEST_SONGS, "held_out", *sorted(
        p.stem for p in SONG_FILES.glob("*.mid"))]))
    parser.add_argument("--no-adapt", action="store_true", help="Skip the --adapt runs (half the time).")
    parser.add_argument("--settings", default=",".join(SETTINGS))
    parser.add_argument("--sizes", default="1000,5000,20000")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        songs = _songs([s for s in args.songs.split(",") if s], [s for s in args.settings.split(",") if s], Path(tmp),
                       adapt=not args.no_adapt)
    result = {"songs": songs, "planning": _planning([int(s) for s in args.sizes.split(",")])}
    text = json.dumps(result, indent=2)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text + "\n", encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
