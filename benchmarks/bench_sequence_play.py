"""`play --model SEQMODEL` against the per-note default on the test songs (sim rig, soft finger).

1. Past performances: every song played once with the default command (per-note planner,
   warm-up on, tempo auto), world seed 0 — what a lab has after playing its repertoire.
2. Fed back: `pianobot fit RUN… --model sequence` over those runs (grouped CV, k = 0…3, the
   per-note GP on the same folds; the CV table is reported).
3. The comparison, same run, world seed 1 for both: the default command, and the same with
   `--model sequence.json`. Per song and overall: F1 (mir_eval, 50 ms), onset RMS (ms) and
   velocity MAE (mapped, MIDI), and the ratios sequence / per-note.

Two worlds (`--worlds`): `default`, the built-in sim rig's, where every keystroke starts from
rest (no context: the sequence model should stand aside), and `repeat` (own world, reported
apart), the same with one context effect written here: a key struck again right after it was
played is still rising and sounds `REPEAT_FACTOR` as loud.

Songs: the play test songs built in code (`pianobot.play.library.TEST_SONGS`), bench_play's
held-out song and `experiments/songs/*.mid`. Results: benchmarks/results/sequence_play.json.

    .venv/bin/python benchmarks/bench_sequence_play.py [--songs ode,twinkle] [--worlds repeat] [--seed 0] [--out FILE]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests" / "play"))
from bench_play import SONG_FILES, _song_paths  # noqa: E402

from pianobot.analysis.sequence.fit import fit_sequence_runs  # noqa: E402
from pianobot.physics.world import World, WorldConfig  # noqa: E402
from pianobot.play import PlayResult, play_rig, play_song  # noqa: E402
from pianobot.play.library import TEST_SONGS  # noqa: E402

RESULTS = HERE / "results" / "sequence_play.json"
METRICS = ("f1", "onset_rms_ms", "velocity_mae")
REPEAT_FACTOR = 0.7


class RepeatWorld:
    """The sim rig's world, where a repeated key sounds `REPEAT_FACTOR` as loud (the MIDI
    velocity, rounded, at least 1): the key is still rising from the previous stroke."""

    def __init__(self, seed: int) -> None:
        rig = play_rig("sim")
        self.inner = World(WorldConfig.model_validate({k: v for k, v in rig.world.items() if k != "preset"}), seed)
        self.previous: int | None = None

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    def keystroke(self, press: Any, vacuum_kpa: float, **kwargs: Any) -> Any:
        stroke = self.inner.keystroke(press, vacuum_kpa, **kwargs)
        note = kwargs.get("note")
        repeat, self.previous = note == self.previous, note
        if not repeat:
            return stroke
        midi = [dataclasses.replace(e, velocity=max(1, round(e.velocity * REPEAT_FACTOR)))
                if e.type == "note_on" and e.velocity > 0 else e for e in stroke.midi]
        return dataclasses.replace(stroke, midi=type(stroke.midi)(midi))


def _world(name: str, seed: int) -> Any:
    return RepeatWorld(seed) if name == "repeat" else None


def _row(result: PlayResult) -> dict[str, Any]:
    score = result.score
    assert score is not None and result.plan.tempo is not None
    frame = result.plan.notes
    return {"f1": score.f1, "onset_rms_ms": score.onset_rms_ms, "velocity_mae": score.velocity_mae,
            "tempo_bpm": result.plan.tempo.played_bpm, "notes": score.notes_target,
            "context_velocity_abs_mean": float(np.abs(frame["context_velocity"]).mean()),
            "context_lead_abs_mean_ms": float(np.abs(frame["context_lead_s"]).mean() * 1e3)}


def compare(names: list[str], world: str, tmp: Path, seed: int = 0) -> dict[str, Any]:
    """Past performances, the fed-back sequence model, and the comparison in one world."""
    data = tmp / world / "data"
    paths = _song_paths(names, tmp)
    past = []
    for name, (path, _) in paths.items():
        past.append(play_song(path, data_dir=data, seed=seed, world=_world(world, seed)).performance.run_id)  # type: ignore[union-attr]
        print(f"{world}: past performance of {name}: {past[-1]}", file=sys.stderr)
    fit = fit_sequence_runs(past, data, out_dir=tmp / world / "models", workers=2)
    assert fit.saved is not None
    print(f"{world}: sequence model k={fit.k} over {fit.n_strokes} strokes in {fit.n_sequences} sequences", file=sys.stderr)
    rows = []
    for name, (path, _) in paths.items():
        per_note = _row(play_song(path, data_dir=data, seed=seed + 1, world=_world(world, seed + 1)))
        sequence = play_song(path, data_dir=data, seed=seed + 1, model=fit.saved, world=_world(world, seed + 1))
        seq = _row(sequence)
        rows.append({"song": name, "per_note": per_note, "sequence": seq, "context": sequence.plan.context})
        print(f"{world} {name}: per-note F1 {per_note['f1']:.3f} onset {per_note['onset_rms_ms']:.1f} ms MAE "
              f"{per_note['velocity_mae']:.2f}; sequence F1 {seq['f1']:.3f} onset {seq['onset_rms_ms']:.1f} ms "
              f"MAE {seq['velocity_mae']:.2f}", file=sys.stderr)
    overall = {model: {m: float(np.mean([r[model][m] for r in rows])) for m in METRICS}
               for model in ("per_note", "sequence")}
    overall["sequence_over_per_note"] = {m: overall["sequence"][m] / overall["per_note"][m]
                                         if overall["per_note"][m] else None for m in METRICS}
    return {"fit": fit.to_dict(), "songs": rows, "overall_mean": overall,
            "at_least_as_good": {m: all((r["sequence"][m] >= r["per_note"][m]) if m == "f1"
                                        else (r["sequence"][m] <= r["per_note"][m]) for r in rows) for m in METRICS}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--songs", default=",".join([*TEST_SONGS, "held_out", *sorted(p.stem for p in SONG_FILES.glob("*.mid"))]))
    parser.add_argument("--worlds", default="default,repeat")
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--seed", type=int, default=0, help="world seed of the past runs; the compared runs use seed + 1")
    args = parser.parse_args()
    names = [s for s in args.songs.split(",") if s]
    result: dict[str, Any] = {"benchmark": "sequence_play",
                              "setting": f"soft finger, built-in sim rig; past runs seed {args.seed}, "
                                         f"compared runs seed {args.seed + 1}"}
    with tempfile.TemporaryDirectory() as tmp:
        for world in [w for w in args.worlds.split(",") if w]:
            result[world] = compare(names, world, Path(tmp), args.seed)
            text = json.dumps(result, indent=2, default=float)
            args.out.parent.mkdir(parents=True, exist_ok=True)
            args.out.write_text(text + "\n", encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
