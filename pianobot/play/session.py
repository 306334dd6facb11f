"""`pianobot play`: song → melody → (warm-up) → plan at a tempo the finger keeps → rig → score.

The default is what a new user types (`pianobot play song.mid`): the built-in sim rig with a
player's moves between keys, the published physics model as the starting point, a warm-up on
the piano that fits the note-on delay and loudness maps (`warmup`), and the fastest tempo at
which every note can be struck in time, never above the written one (`tempo`). A dry run plans
with the starting model only (nothing moves, so nothing is learned) and says so.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd

from pianobot.analysis.learn.files import load_predictor
from pianobot.analysis.learn.physical import PhysicsPredictor
from pianobot.analysis.learn.predictors import StrokePredictor
from pianobot.errors import InputError, check_seed
from pianobot.io.midifile import Melody, Note, Song, melody, read_song, write_performance
from pianobot.physics.model import KeystrokeModel
from pianobot.play.adapt import OnlineAdapter
from pianobot.play.context import SongContext, is_sequence_file
from pianobot.play.dynamics import DYNAMICS_MODES, DynamicsMode
from pianobot.play.figure import piano_roll, warmup_figure
from pianobot.play.naive import plan_naive
from pianobot.play.perform import Performance, Performer, trial_id_for
from pianobot.play.report import write_play_report
from pianobot.play.score import Score, score_performance
from pianobot.play.settings import PlaySettings
from pianobot.play.song_plan import SongPlan, plan_model
from pianobot.play.strokes import stroke_tables
from pianobot.play.tempo import TempoRequest
from pianobot.play.warmup import (
    WarmUp,
    design_warmup,
    fit_warmup,
    survey_size,
    warmup_lab_time_s,
)
from pianobot.progress import NO_PROGRESS, Progress
from pianobot.spec import RigSpec, load_rig
from pianobot.spec.parameters import FINGERS, Finger
from pianobot.spec.rig import Approach, Travel

PlannerName = Literal["model", "naive"]
PLANNERS: tuple[str, ...] = ("model", "naive")
# A player's moves between keys (the built-in sim rig's travel settings are a sweep's: slow, with
# a 50 mm lift): lift just clear of the black keys (~12 mm above the white ones) and move
# briskly, half a UR5's top speed so the finger stays steady. One white key over: ~0.37 s.
PLAYER_TRAVEL = Travel(velocity_mps=0.5, acceleration_mps2=4.0, lift_m=0.012)
# A player's two-segment press: the fast approach at the travel moves' speed, stopping 1 mm above
# the key (the sweeps' default keeps 5 mm and 1.5 s of the spec's motion before contact, to leave
# the keystroke exactly as specified; a player instead warms up on the very strokes it plays).
PLAYER_APPROACH = Approach(velocity_mps=0.5, acceleration_mps2=4.0, clearance_m=0.001, settle_s=0.0)
# A rigid finger's stiffness for the starting model (the published model is the soft finger's):
# stiff enough that the arm's travel reaches the key almost one to one.
RIGID_FINGER_K1_NPM = 5000.0
# The built-in sim rig's world with `--finger rigid`: no vacuum line, ~25x the soft finger's
# stiffness (not the starting model's value: the warm-up is what learns it).
BUILTIN_RIGID_FINGER = {"k1_a_npm": 2000.0, "k1_b_npm_per_kpa": 0.0}


@dataclass(frozen=True)
class PlayResult:
    """Everything one `play` produced."""

    song: Song
    melody: Melody
    plan: SongPlan
    performance: Performance | None  # None for a dry run
    score: Score | None
    warnings: tuple[str, ...]
    files: dict[str, str] = field(default_factory=dict)
    model: str = "published physics model"
    warmup: WarmUp | None = None
    prior_plan: SongPlan | None = None  # the plan before the warm-up (its tempo is the dry run's)

    def to_dict(self) -> dict[str, Any]:
        """The JSON `play --json` prints: the score keys at the top level."""
        out: dict[str, Any] = {}
        if self.score is not None:
            out.update(self.score.to_dict())
        plan = self.plan.summary()
        out.update({
            "planner": self.plan.planner,
            "model": self.model,
            "tempo": plan["tempo"],
            "dynamics": plan["dynamics"],
            "mapping": None if plan["dynamics"] is None else plan["dynamics"]["text"],
            "plan": plan,
            "warmup": None if self.warmup is None else self.warmup.summary(),
            "song": {"source": self.song.source, "tempo_bpm": self.song.tempo_bpm,
                     "notes": len(self.song.notes), "melody_notes": len(self.melody.notes),
                     "unplayable": len(self.song.unplayable)},
            "warnings": list(self.warnings),
            "files": self.files,
        })
        if self.prior_plan is not None and self.prior_plan.tempo is not None:
            out["tempo_before_warmup"] = self.prior_plan.tempo.to_dict()
        if self.performance is not None:
            p = self.performance
            out.update({"run_id": p.run_id, "status": p.status, "reason": p.reason,
                        "observed_recovery_s": p.recovery_s, "rig_warnings": list(p.rig_warnings)})
            if p.adaptation:
                out["adaptation"] = {"updates": len(p.adaptation), "final": {
                    k: v for k, v in p.adaptation[-1].items() if k.startswith(("velocity_", "lead_"))}}
        return out


def play_rig(rig: str | Path | RigSpec, finger: Finger = "soft") -> RigSpec:
    """The rig to play on: "sim" (the built-in sim rig) or a rig file, with a player's moves.

    On the built-in rig, `finger="rigid"` simulates a rigid finger (`BUILTIN_RIGID_FINGER`, as
    `experiments/rigs/sim-rigid.yaml`): the soft finger's world would not reach the key with a
    rigid finger's shallow strokes. A rig file's world is used as written.

    The built-in travel and approach settings are a sweep's (slow, with a 50 mm lift between
    keys; fast approaches that keep 5 mm and 1.5 s of the spec's motion). A simulated rig whose
    file says nothing about `travel:` or `approach:` (the built-in one included) plays with a
    player's moves instead (`PLAYER_TRAVEL`, `PLAYER_APPROACH`); sweeps keep theirs. Settings a
    rig file writes, and every real rig's, are used as written: those are the lab's.
    """
    spec = rig if isinstance(rig, RigSpec) else _load_rig(rig)
    if spec.kind == "sim":
        player = {"travel": PLAYER_TRAVEL, "approach": PLAYER_APPROACH}
        spec = spec.model_copy(update={k: v for k, v in player.items() if k not in spec.model_fields_set})
        if finger == "rigid" and isinstance(rig, str) and rig == "sim":
            msd = {**spec.world.get("msd", {}), **BUILTIN_RIGID_FINGER}
            spec = spec.model_copy(update={"world": {**spec.world, "msd": msd}})
    return spec


def _load_rig(rig: str | Path) -> RigSpec:
    if str(rig) == "sim":
        return load_rig("sim")
    if not Path(rig).is_file():
        raise InputError("rig file not found", str(rig))
    return load_rig(rig)


#: Silence before a song's first note longer than this is skipped (seconds on the song clock).
MAX_LEAD_IN_S = 2.0


def load_song(path: Path, *, tempo_scale: float = 1.0, transpose: int = 0, track: int | None = None,
              rule: str = "highest") -> tuple[Song, Melody]:
    """Read a song and reduce it to one finger's melody; InputError if nothing is playable."""
    song = read_song(path, tempo_scale=tempo_scale, transpose=transpose, track=track)
    line = melody(song.notes, rule=rule)
    if not line.notes:
        reasons = [f"{len(song.unplayable)} outside the piano's keys"] if song.unplayable else []
        reasons += [w for w in song.warnings if "outside the piano" not in w]
        detail = f" ({'; '.join(reasons)})" if reasons else ""
        raise InputError(f"the song has no playable notes{detail}", str(path))
    return song, line.without_lead_in(MAX_LEAD_IN_S)


#: A level whose survey heard fewer notes than this is one the warm-up cannot learn (`fit_warmup`).
MIN_HEARD_PER_LEVEL = 3


def _heard(survey: pd.DataFrame, level: float) -> int:
    """How many notes the warm-up heard at a vacuum level."""
    at = survey[np.isclose(survey["vacuum_kpa"].to_numpy(float), level)]
    return int((at["status"] == "ok").sum())


def play_song(
    song_path: Path,
    *,
    data_dir: Path,
    model: Path | StrokePredictor | SongContext | None = None,
    planner: str = "model",
    adapt: bool = False,
    dry_run: bool = False,
    tempo: str | TempoRequest | None = None,
    tempo_scale: float = 1.0,
    transpose: int = 0,
    track: int | None = None,
    dynamics: str = "mapped",
    rig: str | Path | RigSpec = "sim",
    finger: str | None = None,
    warmup: int | None = None,
    seed: int | None = None,
    plot: Path | None = None,
    settings: PlaySettings | None = None,
    world: Any | None = None,
    progress: Progress = NO_PROGRESS,
    on_warning: Callable[[str], None] | None = None,
) -> PlayResult:
    """Plan (and unless `dry_run`, warm up, play and score) a song; see `pianobot play --help`.

    `model` is a model/predictor file, a StrokePredictor, or None for the published physics
    model (the warm-up's starting point); or a sequence model (file of `fit --model sequence`,
    told by its schema, or a `SongContext`): then the per-note maps start from the published
    model as usual and each note is planned with its context (`pianobot.play.context`). `tempo`: None (auto unless `tempo_scale` is given),
    "auto", "written" or bpm. `warmup`: keystrokes per vacuum level (None: the settings', 0: none).
    `world` replaces the sim rig's physics World (tests). `on_warning` hears each warning when it is
    known, before the motion it concerns: the song's (chords reduced to a melody) once it is read,
    the rig's (e.g. the UR's speed slider below 100 %) once it is open, the plan's (the written
    tempo is too fast, and the one played instead) after the warm-up, before the song;
    `PlayResult.warnings` holds the song's and the plan's again.
    """
    if planner not in PLANNERS:
        raise InputError(f"planner should be one of {', '.join(PLANNERS)}, got {planner!r}", "--planner")
    if dynamics not in DYNAMICS_MODES:
        raise InputError(f"dynamics should be one of {', '.join(DYNAMICS_MODES)}, got {dynamics!r}", "--dynamics")
    if adapt and planner == "naive":
        raise InputError("--adapt corrects the model planner; the naive planner has no model", "--adapt")
    if finger is not None and finger not in FINGERS:
        raise InputError(f"finger should be one of {', '.join(FINGERS)}, got {finger!r}", "--finger")
    if warmup is not None and not (warmup == 0 or MIN_HEARD_PER_LEVEL <= warmup <= 200):
        raise InputError(f"warm-up keystrokes per vacuum level should be 0 (none) or {MIN_HEARD_PER_LEVEL} to 200 "
                         f"(a level is learnt from {MIN_HEARD_PER_LEVEL} sounded notes), got {warmup}", "--warmup")
    check_seed(seed)
    settings = settings or PlaySettings()
    if finger is not None:
        settings = settings.model_copy(update={"finger": finger})
    strokes = settings.warmup_strokes if warmup is None else warmup
    request = tempo if isinstance(tempo, TempoRequest) else TempoRequest.parse(tempo)
    if request.mode == "bpm" and tempo_scale != 1.0:  # the scale used to be ignored without a word
        raise InputError(f"--tempo {request.describe()} sets the tempo itself; --tempo-scale scales the written one: "
                         "give one of them", "--tempo-scale")
    if tempo is None and tempo_scale != 1.0:
        request = TempoRequest("written", None, True)  # --tempo-scale alone asks for that tempo
    rig_spec = play_rig(rig, settings.finger)
    song, line = load_song(Path(song_path), tempo_scale=tempo_scale, transpose=transpose, track=track,
                           rule=settings.melody_rule)
    tell = on_warning or (lambda _: None)
    for text in (*song.warnings, *line.warnings):
        tell(text)
    mode: DynamicsMode = "absolute" if dynamics == "absolute" else "mapped"
    context = _sequence_context(model, planner, adapt)
    if context is not None:
        model = None
        if not context.used:
            tell(context.describe())
    predictor: StrokePredictor | None = None
    if planner == "naive":
        plan = plan_naive(line.notes, settings, rig_spec, tempo=request, written_bpm=song.tempo_bpm)
        label, strokes = "none (naive: 0.001·v m/s)", 0
    else:
        predictor, label = starting_model(model, settings.finger)  # type: ignore[arg-type]
        if context is not None:
            label = f"sequence model {context.source} over the {label}"
        plan = plan_model(line.notes, predictor, settings, rig_spec, dynamics=mode, tempo=request,
                          written_bpm=song.tempo_bpm, context=context)
    prior = plan
    if dry_run:
        notes = list(plan.warnings)
        if strokes:
            notes.append(f"planned with the {label} (a dry run moves nothing); before playing, a warm-up of "
                         f"{strokes} keystroke(s) per vacuum level fits this piano and the plan follows it")
        return PlayResult(song, line, plan, None, None, (*song.warnings, *line.warnings, *notes), {}, label,
                          prior_plan=prior)
    song_key = hashlib.sha256(Path(song_path).read_bytes()).hexdigest()[:16]
    design: list[Any] = []
    focus: list[Any] = []
    levels: list[float] = []
    if strokes and plan.geometry is not None:
        levels = sorted({float(v) for v in plan.played["vacuum_kpa"]}) or sorted(plan.tables)
        design = design_warmup([n.pitch for n in line.notes], plan.geometry, levels, settings, rig_spec,
                               strokes_per_level=strokes, song_key=song_key)
    meta = {
        "song": {"path": str(Path(song_path).resolve()), "sha256": song_key, "tempo_scale": tempo_scale,
                 "transpose": transpose, "track": track, "written_bpm": song.tempo_bpm},
        "planner": planner, "model": label, "adapt": adapt, "finger": settings.finger,
        "settings": settings.model_dump(mode="json"), "tempo_request": request.describe(),
        "plan_summary_before_warmup": plan.summary(),
        "warmup_planned": {"strokes": len(design),
                           "estimated_lab_time_s": warmup_lab_time_s(design, rig_spec, strokes)},
    }
    initial = _initial_plan(design, plan, song_key)
    adapter = OnlineAdapter() if adapt else None
    name = f"play-{Path(song_path).stem}-{planner}{'-adapt' if adapt else ''}"
    warm: WarmUp | None = None
    with Performer(rig_spec, data_dir=data_dir, name=name, song_key=song_key, meta=meta, plan=initial,
                   seed=seed, world=world, progress=progress, on_warning=tell) as performer:
        if design:
            survey, survey_s = performer.warm_up(design)
            tables, excluded = plan.tables, set[float]()
            while predictor is not None:  # a level this piano never sounds at: plan without it (model planner)
                deaf = {lv for lv in levels if _heard(survey, lv) < MIN_HEARD_PER_LEVEL} - excluded
                usable = {lv: t for lv, t in tables.items() if lv not in excluded | deaf}
                if not deaf or not usable:
                    break
                excluded |= deaf
                plan = plan_model(line.notes, predictor, settings, rig_spec, dynamics=mode, tables=usable,
                                  tempo=request, written_bpm=song.tempo_bpm, context=context)
                more_levels = [lv for lv in sorted({float(v) for v in plan.played["vacuum_kpa"]}) if lv not in levels]
                if not more_levels:
                    break
                tell(f"the warm-up heard no note at {', '.join(f'{d:g}' for d in sorted(deaf))} kPa: it warms up at "
                     f"{', '.join(f'{lv:g}' for lv in more_levels)} kPa too")
                more = design_warmup([n.pitch for n in line.notes], plan.geometry, more_levels, settings,  # type: ignore[arg-type]
                                     rig_spec, strokes_per_level=strokes, song_key=song_key, start=len(design))
                extra, extra_s = performer.warm_up(more)
                design, levels = design + more, levels + more_levels
                survey, survey_s = pd.concat([survey, extra], ignore_index=True), survey_s + extra_s
            heard = [lv for lv in levels if _heard(survey, lv) >= MIN_HEARD_PER_LEVEL] or levels
            focus = design_warmup([n.pitch for n in line.notes], plan.geometry, heard, settings,  # type: ignore[arg-type]
                                  rig_spec, strokes_per_level=strokes, song_key=song_key, survey=survey)
            mapped, mapped_s = performer.warm_up(focus) if focus else (survey.iloc[:0], 0.0)
            rows = pd.concat([survey, mapped], ignore_index=True)
            # scikit-learn takes seeds below 2**32; the world's seed may be any up to 2**63 - 1
            warm = fit_warmup(rows, plan.geometry, lab_time_s=survey_s + mapped_s, seed=performer.seed % 2**32,  # type: ignore[arg-type]
                              survey=survey_size(strokes))
            if context is not None:
                context = context.calibrated_on(rows)
            tables = stroke_tables(warm.predictor, settings, rig_spec, warm.geometry, levels=warm.levels_kpa,
                                   speed_ranges=warm.speed_ranges_mps)
            plan = plan_model(line.notes, warm.predictor, settings, rig_spec, dynamics=mode, tables=tables,
                              tempo=request, written_bpm=song.tempo_bpm, context=context)
        song_plan = plan.notes.assign(trial_id=[trial_id_for(song_key, int(i)) for i in plan.notes["note_index"]])
        _write_parquet(song_plan, performer.run_path / "song_plan.parquet")
        if warm is not None:
            performer.replan(_initial_plan(design + focus, plan, song_key))
        performer.writer.update_meta(plan_summary=plan.summary(), warnings=list(plan.warnings),
                                     warmup=None if warm is None else warm.summary())
        for text in plan.warnings:  # the tempo played and why, before the song starts
            tell(text)
        performance = performer.play(plan, adapter)
    assert plan.tempo is not None
    target = _at_tempo(line.notes, plan.tempo.scale)
    score = score_performance(target, performance.notes, plan.notes["target_velocity"].to_numpy(float),
                              tempo_bpm=plan.tempo.played_bpm, skipped=list(plan.notes["status"] == "skip"))
    files = _write_outputs(performance, target, score, plan, plot, label, warm)
    warnings = (*song.warnings, *line.warnings, *plan.warnings, *_poor_performance(score, warm is None))
    return PlayResult(song, line, plan, performance, score, warnings, files, label, warm, prior)


#: Below this share of the planned notes heard on time, the output says the model missed the piano.
POOR_SHARE = 0.5


def _poor_performance(score: Score, no_warmup: bool) -> tuple[str, ...]:
    """One line when most planned notes were not heard on time (a model that does not fit the
    piano: silent strokes, or every note late), with what to do about it."""
    status = score.per_note["status"] if len(score.per_note) else pd.Series(dtype=str)
    planned = int((status != "skipped").sum())
    on_time = int((status == "matched").sum())
    if planned == 0 or on_time >= POOR_SHARE * planned:
        return ()
    missed, late = int((status == "missed").sum()), int(status.isin(["late", "early"]).sum())
    hint = ("play with a warm-up (the default) so the model learns this piano" if no_warmup
            else "the warm-up's model does not fit this piano; `pianobot play --dry-run` shows the plan")
    return (f"only {on_time} of {planned} planned note(s) were heard on time ({missed} not heard, {late} off by "
            f"more than 50 ms): {hint}",)


def _sequence_context(model: Path | StrokePredictor | SongContext | None, planner: str,
                      adapt: bool) -> SongContext | None:
    """The sequence model `--model` names, if it names one (by the file's schema)."""
    if isinstance(model, SongContext):
        context = model
    elif isinstance(model, str | Path) and is_sequence_file(Path(model)):
        context = SongContext.load(Path(model))
    else:
        return None
    if planner == "naive":
        raise InputError("the naive planner uses no model; a sequence model needs --planner model", "--model")
    if adapt:
        raise InputError("--adapt corrects each note from what it hears, a sequence model from the notes before it: "
                         "give one of them", "--adapt")
    return context


def starting_model(model: Path | StrokePredictor | None, finger: Finger) -> tuple[StrokePredictor, str]:
    """The model the plan starts from and its label: a file, a predictor, or the published
    physics model (with a rigid finger's stiffness for the rigid finger)."""
    if model is None:
        if finger == "rigid":
            study = KeystrokeModel.study()
            msd = study.msd.replace(k1_a_npm=RIGID_FINGER_K1_NPM, k1_b_npm_per_kpa=0.0)
            return PhysicsPredictor(study.replace(msd=msd)), "published physics model with a rigid finger"
        return PhysicsPredictor.published(), "published physics model"
    if isinstance(model, str | Path):
        return load_predictor(Path(model)), str(model)
    return model, type(model).__name__


def _at_tempo(notes: tuple[Note, ...], scale: float) -> list[Note]:
    """The melody on the song clock of the tempo played (times × scale)."""
    return [Note(n.pitch, n.onset_s * scale, n.offset_s * scale, n.velocity, n.track, n.channel) for n in notes]


def _initial_plan(design: list[Any], plan: SongPlan, song_key: str) -> pd.DataFrame:
    """plan.parquet: the warm-up keystrokes and the song's notes (the plan before the warm-up
    when the run is created; after the warm-up, its strokes and the song as it will be played)."""
    warm = pd.DataFrame([{"trial_id": t.trial_id, "index": t.index, "phase": "warmup", "pitch": t.note,
                          **t.parameters()} for t in design])
    song = plan.notes.assign(trial_id=[trial_id_for(song_key, int(i)) for i in plan.notes["note_index"]],
                             phase="song")
    return pd.concat([warm, song], ignore_index=True) if len(warm) else song


def _write_parquet(frame: pd.DataFrame, path: Path) -> None:
    """Write atomically: a reader sees the whole file or none."""
    temp = path.with_name(f".{path.name}.tmp")
    frame.to_parquet(temp, index=False)
    os.replace(temp, path)


def _write_outputs(performance: Performance, target: list[Note], score: Score, plan: SongPlan,
                   plot: Path | None, label: str, warm: WarmUp | None) -> dict[str, str]:
    """performance.mid, the piano roll, the warm-up figure, report.html, score.json and the per-note table."""
    root = performance.run_path
    files = {"performance_mid": str(write_performance(root / "performance.mid", performance.notes))}
    tempo = f" at {plan.tempo.played_bpm:.4g} bpm" if plan.tempo is not None else ""
    title = (f"{plan.planner} planner{tempo}: F1 {score.f1:.2f}, onset RMS {score.onset_rms_ms:.0f} ms, "
             f"velocity MAE {score.velocity_mae:.1f}")
    status = list(score.per_note["status"])
    files["piano_roll"] = str(piano_roll(target, performance.notes, root / "pianoroll.png", title=title, status=status))
    if plot is not None:
        files["plot"] = str(piano_roll(target, performance.notes, Path(plot), title=title, status=status))
    if warm is not None:
        files["warmup_plot"] = str(warmup_figure(warm.trials, warm.predictor, root / "warmup.png"))
    score.per_note.to_parquet(root / "score_notes.parquet", index=False)
    if performance.adaptation:
        pd.DataFrame(performance.adaptation).to_parquet(root / "adaptation.parquet", index=False)
        files["adaptation"] = str(root / "adaptation.parquet")
    files["report"] = str(write_play_report(root / "report.html", performance=performance, plan=plan, score=score,
                                            target=target, warmup=warm, model=label, title=title))
    payload = {**score.to_dict(), "planner": plan.planner, "model": label, "plan": plan.summary(),
               "warmup": None if warm is None else warm.summary(), "per_note": score.per_note_records()}
    (root / "score.json").write_text(json.dumps(payload, indent=2, default=_json_default) + "\n", encoding="utf-8")
    files["score"] = str(root / "score.json")
    return files


def _json_default(value: Any) -> Any:
    if hasattr(value, "item"):
        return value.item()
    return str(value)
