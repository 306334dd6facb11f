"""`pianobot play`: song file → melody → plan → rig → performance.mid + piano roll + score."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from pianobot.analysis.learn.predictors import PhysicsPredictor, StrokePredictor, load_predictor
from pianobot.errors import InputError
from pianobot.io.midifile import Melody, Song, melody, read_song, write_performance
from pianobot.play.adapt import OnlineAdapter
from pianobot.play.dynamics import DYNAMICS_MODES, DynamicsMode
from pianobot.play.figure import piano_roll
from pianobot.play.naive import plan_naive
from pianobot.play.perform import Performance, perform
from pianobot.play.plan import Plan, plan_model
from pianobot.play.score import Score, score_performance
from pianobot.play.settings import PlaySettings
from pianobot.spec import RigSpec, load_rig

PlannerName = Literal["model", "naive"]
PLANNERS: tuple[str, ...] = ("model", "naive")


@dataclass(frozen=True)
class PlayResult:
    """Everything one `play` produced."""

    song: Song
    melody: Melody
    plan: Plan
    performance: Performance | None  # None for a dry run
    score: Score | None
    warnings: tuple[str, ...]
    files: dict[str, str] = field(default_factory=dict)
    model: str = "published physics model"

    def to_dict(self) -> dict[str, Any]:
        """The JSON `play --json` prints: the score keys at the top level."""
        out: dict[str, Any] = {}
        if self.score is not None:
            out.update(self.score.to_dict())
        plan = self.plan.summary()
        out.update({
            "planner": self.plan.planner,
            "model": self.model,
            "dynamics": plan["dynamics"],
            "mapping": None if plan["dynamics"] is None else plan["dynamics"]["text"],
            "plan": plan,
            "song": {"source": self.song.source, "tempo_bpm": self.song.tempo_bpm,
                     "notes": len(self.song.notes), "melody_notes": len(self.melody.notes),
                     "unplayable": len(self.song.unplayable)},
            "warnings": list(self.warnings),
            "files": self.files,
        })
        if self.performance is not None:
            p = self.performance
            out.update({"run_id": p.run_id, "status": p.status, "reason": p.reason,
                        "observed_recovery_s": p.recovery_s, "rig_warnings": list(p.rig_warnings)})
            if p.adaptation:
                out["adaptation"] = {"updates": len(p.adaptation), "final": {
                    k: v for k, v in p.adaptation[-1].items() if k.startswith(("velocity_", "lead_"))}}
        return out


def play_rig(rig: str | Path | RigSpec) -> RigSpec:
    """The rig to play on: "sim" is the built-in sim rig exactly as documented, else a rig file.

    Nothing is overridden: the built-in rig moves between keys like a sweep (slowly, with a
    50 mm lift); `experiments/rigs/sim-play.yaml` holds the travel settings of a player.
    """
    if isinstance(rig, RigSpec):
        return rig
    if str(rig) == "sim":
        return load_rig("sim")
    if not Path(rig).is_file():
        raise InputError("rig file not found", str(rig))
    return load_rig(rig)


def load_song(path: Path, *, tempo_scale: float = 1.0, transpose: int = 0, track: int | None = None,
              rule: str = "highest") -> tuple[Song, Melody]:
    """Read a song and reduce it to one finger's melody; InputError if nothing is playable."""
    song = read_song(path, tempo_scale=tempo_scale, transpose=transpose, track=track)
    line = melody(song.notes, rule=rule)
    if not line.notes:
        detail = f" ({len(song.unplayable)} outside the piano's keys)" if song.unplayable else ""
        raise InputError(f"the song has no playable notes{detail}", str(path))
    return song, line


def play_song(
    song_path: Path,
    *,
    data_dir: Path,
    model: Path | StrokePredictor | None = None,
    planner: str = "model",
    adapt: bool = False,
    dry_run: bool = False,
    tempo_scale: float = 1.0,
    transpose: int = 0,
    track: int | None = None,
    dynamics: str = "mapped",
    rig: str | Path | RigSpec = "sim",
    seed: int | None = None,
    plot: Path | None = None,
    settings: PlaySettings | None = None,
    world: Any | None = None,
) -> PlayResult:
    """Plan (and unless `dry_run`, play and score) a song; see `pianobot play --help`.

    `model` is a model/predictor file, a StrokePredictor, or None for the published physics
    model. `world` replaces the sim rig's physics World (tests).
    """
    if planner not in PLANNERS:
        raise InputError(f"planner should be one of {', '.join(PLANNERS)}, got {planner!r}", "--planner")
    if dynamics not in DYNAMICS_MODES:
        raise InputError(f"dynamics should be one of {', '.join(DYNAMICS_MODES)}, got {dynamics!r}", "--dynamics")
    if adapt and planner == "naive":
        raise InputError("--adapt corrects the model planner; the naive planner has no model", "--adapt")
    settings = settings or PlaySettings()
    rig_spec = play_rig(rig)
    song, line = load_song(Path(song_path), tempo_scale=tempo_scale, transpose=transpose, track=track,
                           rule=settings.melody_rule)
    if planner == "naive":
        plan, label = plan_naive(line.notes, settings, rig_spec), "none (naive: 0.001·v m/s)"
    else:
        predictor, label = _predictor(model)
        mode: DynamicsMode = "absolute" if dynamics == "absolute" else "mapped"
        plan = plan_model(line.notes, predictor, settings, rig_spec, dynamics=mode)
    warnings = (*song.warnings, *line.warnings, *plan.warnings)
    if dry_run:
        return PlayResult(song, line, plan, None, None, warnings, {}, label)
    song_key = hashlib.sha256(Path(song_path).read_bytes()).hexdigest()[:16]
    meta = {
        "song": {"path": str(Path(song_path).resolve()), "sha256": song_key, "tempo_scale": tempo_scale,
                 "transpose": transpose, "track": track},
        "planner": planner, "model": label, "adapt": adapt,
        "settings": settings.model_dump(mode="json"), "plan_summary": plan.summary(),
        "warnings": list(warnings),
    }
    adapter = OnlineAdapter() if adapt else None
    name = f"play-{Path(song_path).stem}-{planner}{'-adapt' if adapt else ''}"
    performance = perform(plan, rig_spec, data_dir=data_dir, name=name, song_key=song_key, meta=meta,
                          seed=seed, world=world, adapter=adapter)
    score = score_performance(line.notes, performance.notes, plan.notes["target_velocity"].to_numpy(float))
    files = _write_outputs(performance, line, score, plan, plot, label)
    return PlayResult(song, line, plan, performance, score, warnings, files, label)


def _predictor(model: Path | StrokePredictor | None) -> tuple[StrokePredictor, str]:
    if model is None:
        return PhysicsPredictor.published(), "published physics model"
    if isinstance(model, str | Path):
        return load_predictor(Path(model)), str(model)
    return model, type(model).__name__


def _write_outputs(performance: Performance, line: Melody, score: Score, plan: Plan,
                   plot: Path | None, label: str) -> dict[str, str]:
    """performance.mid, the piano roll, score.json and the per-note table beside the run."""
    root = performance.run_path
    files = {"performance_mid": str(write_performance(root / "performance.mid", performance.notes))}
    title = f"{plan.planner} planner: F1 {score.f1:.2f}, onset RMS {score.onset_rms_ms:.0f} ms, velocity MAE {score.velocity_mae:.1f}"
    files["piano_roll"] = str(piano_roll(line.notes, performance.notes, root / "pianoroll.png", title=title))
    if plot is not None:
        files["plot"] = str(piano_roll(line.notes, performance.notes, Path(plot), title=title))
    score.per_note.to_parquet(root / "score_notes.parquet", index=False)
    if performance.adaptation:
        import pandas as pd

        pd.DataFrame(performance.adaptation).to_parquet(root / "adaptation.parquet", index=False)
        files["adaptation"] = str(root / "adaptation.parquet")
    payload = {**score.to_dict(), "planner": plan.planner, "model": label, "plan": plan.summary()}
    (root / "score.json").write_text(json.dumps(payload, indent=2, default=_json_default) + "\n", encoding="utf-8")
    files["score"] = str(root / "score.json")
    return files


def _json_default(value: Any) -> Any:
    if hasattr(value, "item"):
        return value.item()
    return str(value)
