"""Command `play`: warm up on the piano, play a MIDI song at a tempo the finger keeps, score it.

Warnings (the tempo chosen and why, chords reduced to a melody, notes that cannot be played in
time, clipped loudness) go to stderr, one line each; the score (or with `--dry-run` the plan,
its feasible tempo and limiting notes) to stdout.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from pianobot.cli.common import (
    DEFAULT_DATA,
    Column,
    DataDir,
    JsonFlag,
    NoProgressFlag,
    command_progress,
    emit_json,
    figure_path,
    print_fields,
    print_table,
    say,
    say_written,
)
from pianobot.play import PlayResult, play_song
from pianobot.play.perform import PerformanceStopped
from pianobot.play.tempo import note_numbers
from pianobot.play.warmup import WarmUpFailed

# (column, heading with unit, scale, format, priority): priority 0 always shows, the highest
# number is dropped first on a narrow terminal (`--json` keeps every column, plan_notes).
SONG_PLAN_TABLE: tuple[tuple[str, str, float, str, int], ...] = (
    ("note_index", "#", 1.0, "d", 0),
    ("pitch", "pitch", 1.0, "d", 0),
    ("onset_s", "onset (s)", 1.0, ".2f", 0),
    ("song_velocity", "song vel.", 1.0, ".0f", 3),
    ("target_velocity", "target vel.", 1.0, ".0f", 0),
    ("vacuum_kpa", "vacuum (kPa)", 1.0, ".0f", 2),
    ("down_velocity_mps", "down (mm/s)", 1e3, ".1f", 0),
    ("hold_s", "hold (ms)", 1e3, ".0f", 3),
    ("predicted_velocity", "predicted vel.", 1.0, ".1f", 1),
    ("predicted_lead_s", "lead (ms)", 1e3, ".0f", 1),
    ("start_s", "motion start (s)", 1.0, ".3f", 2),
    ("tempo_limit_bpm", "limit (bpm)", 1.0, ".0f", 0),
    ("status", "status", 1.0, "", 0),
    ("reason", "reason", 1.0, "", 0),
)


def _fmt(value: Any, scale: float = 1.0, spec: str = ".3g") -> str:
    if isinstance(value, bool) or value is None:
        return "-" if value is None else str(value)
    if isinstance(value, int | float):
        if isinstance(value, float) and math.isnan(value):
            return "-"
        if spec == "d" or (isinstance(value, int) and scale == 1.0):
            return str(int(value))  # a count reads 3012, never 3.01e+03
        return format(float(value) * scale, spec or ".3g")
    return str(value)


def _tempo_line(result: PlayResult) -> str:
    tempo = result.plan.tempo
    if tempo is None:
        return ""
    feasible = "unknown (no model)" if math.isnan(tempo.feasible_bpm) else (
        "unbounded" if math.isinf(tempo.feasible_bpm) else f"{tempo.feasible_bpm:.4g} bpm")
    limiting = note_numbers(tempo.limiting_notes) or "-"
    return (f"tempo: written {tempo.written_bpm:.4g} bpm, fastest feasible {feasible} "
            f"(limiting notes: {limiting}), playing at {tempo.played_bpm:.4g} bpm ({tempo.request.describe()})")


def _print_plan(result: PlayResult) -> None:
    notes = result.plan.notes
    specs = [c for c in SONG_PLAN_TABLE if c[0] in notes.columns]
    columns = [Column(head, prio, "left" if name in ("status", "reason") else "right",
                      wrap=name == "reason") for name, head, _, _, prio in specs]
    # Notes are counted from 1 on screen, as in every message (from 0 in files and --json).
    rows = [[_fmt(row[name] + 1 if name == "note_index" else row[name], scale, spec)
             for name, _, scale, spec, _ in specs]
            for _, row in notes.iterrows()]
    print_table(columns, rows, title=f"{result.plan.planner} plan of {result.song.source}")
    summary = result.plan.summary()
    geometry = summary["geometry"] or {}
    say(f"mapping: {summary['dynamics']['text'] if summary['dynamics'] else 'none'}; "
        f"{summary['planned']} of {summary['notes']} notes planned, {summary['skipped']} skipped; "
        f"stroke: hover {geometry.get('distance_m', float('nan')) * 1e3:.0f} mm, "
        f"{geometry.get('acceleration_mps2', float('nan')):g} m/s², "
        f"up {geometry.get('up_velocity_mps', float('nan')) * 1e3:.0f} mm/s")
    say(_tempo_line(result))


def _print_score(result: PlayResult) -> None:
    assert result.score is not None and result.performance is not None
    fields: list[tuple[str, Any]] = []
    for key, value in result.score.to_dict().items():
        if isinstance(value, dict):
            fields.extend((f"{key}.{sub}", _fmt(inner)) for sub, inner in value.items())
        else:
            fields.append((key, _fmt(value)))
    mapping = result.plan.summary()["dynamics"]
    fields.append(("mapping", mapping["text"] if mapping else "none (velocity → speed)"))
    print_fields(fields, title=f"{result.plan.planner} planner on {result.song.source}")
    if result.warmup is not None:
        w = result.warmup.summary()
        mae, lead = w.get("velocity_mae_held_out", math.nan), w.get("lead_rmse_ms_held_out", math.nan)
        held = (f"velocity MAE {mae:.2f}, lead RMSE {lead:.1f} ms" if math.isfinite(mae) and math.isfinite(lead)
                else "n/a (too few sounded strokes to hold any out)")
        say(f"warm-up: {w['strokes']} keystrokes ({w['sounded']} sounded) in {w['lab_time_s']:.1f} s of lab time; "
            f"fit on strokes held out: {held}")
    say(_tempo_line(result))
    say(f"run {result.performance.run_id}: {result.performance.status}")
    for what, path in result.files.items():
        say_written(what.replace("_", " "), path)


def play(
    song: Annotated[Path, typer.Argument(help="A type-0 or type-1 MIDI file.")],
    data: DataDir = DEFAULT_DATA,
    json_out: JsonFlag = False,
    no_progress: NoProgressFlag = False,
    model: Annotated[Path | None, typer.Option("--model", help="Model or predictor file to start from (default: the published physics model), or a sequence model (fit --model sequence) to plan each note with the notes before it.")] = None,
    planner: Annotated[str, typer.Option("--planner", help="model | naive (the study's demo logic).")] = "model",
    adapt: Annotated[bool, typer.Option("--adapt", help="Keep correcting the model from the piano's MIDI during the song.")] = False,
    dry_run: Annotated[bool, typer.Option("--dry-run", help="Print the plan, the fastest feasible tempo and the notes that limit it; move nothing.")] = False,
    tempo: Annotated[str | None, typer.Option("--tempo", help="auto (default: the fastest tempo at which every note can be struck in time, never above the written one) | written (skips what cannot keep up) | beats per minute.")] = None,
    tempo_scale: Annotated[float, typer.Option("--tempo-scale", help="Multiply the written tempo (0.5 = half speed); alone, plays at that tempo.")] = 1.0,
    warmup: Annotated[int | None, typer.Option("--warmup", help="Warm-up keystrokes per vacuum level before the song (default 12).")] = None,
    no_warmup: Annotated[bool, typer.Option("--no-warmup", help="Play with the starting model as it is.")] = False,
    finger: Annotated[str | None, typer.Option("--finger", help="soft (default) | rigid: the safety envelope and stroke defaults (on the built-in rig, also the simulated finger).")] = None,
    transpose: Annotated[int, typer.Option("--transpose", help="Semitones to add to every note.")] = 0,
    track: Annotated[int | None, typer.Option("--track", help="Play only this track (0-based).")] = None,
    dynamics: Annotated[str, typer.Option("--dynamics", help="mapped (song range → reachable range) | absolute (clip).")] = "mapped",
    rig: Annotated[str, typer.Option("--rig", help="sim (the built-in simulated rig with a player's moves between keys) or a rig file.")] = "sim",
    seed: Annotated[int | None, typer.Option("--seed", help="Seed of the simulated world.")] = None,
    plot: Annotated[Path | None, typer.Option("--plot", help="Also write the piano roll here (PNG).")] = None,
) -> None:
    """Warm up on the piano, play a MIDI song at a tempo the finger can keep, and score it."""
    if no_warmup and warmup not in (None, 0):
        from pianobot.errors import InputError

        raise InputError("give either --warmup N or --no-warmup", "--no-warmup")
    figure_path(plot)  # before anything moves: a figure it cannot write would lose the scores
    said: list[str] = []

    def warn(line: str) -> None:  # as soon as it is known: before the motion it concerns
        said.append(line)
        print(f"warning: {line}", file=sys.stderr, flush=True)

    try:
        result = play_song(song, data_dir=data, model=model, planner=planner, adapt=adapt, dry_run=dry_run,
                           tempo=tempo, tempo_scale=tempo_scale, transpose=transpose, track=track,
                           dynamics=dynamics, rig=rig, finger=finger, warmup=0 if no_warmup else warmup, seed=seed,
                           plot=plot, progress=command_progress(json_out, no_progress), on_warning=warn)
    except WarmUpFailed as exc:  # the run is stored (status failed) with the warm-up's keystrokes
        print(f"error: warm-up: {exc}", file=sys.stderr)
        raise typer.Exit(1) from None
    except PerformanceStopped as exc:  # a lost connection, a protective stop in the warm-up
        print(f"error: the rig stopped: {exc}", file=sys.stderr)
        raise typer.Exit(1) from None
    except KeyboardInterrupt:
        print("error: interrupted (Ctrl-C): what was played is kept in its run (`pianobot runs` lists it)",
              file=sys.stderr)
        raise typer.Exit(130) from None
    for line in result.warnings:
        if line not in said:
            warn(line)
    if json_out:
        payload = result.to_dict()
        if dry_run:
            payload["plan_notes"] = result.plan.notes.to_dict(orient="records")
        emit_json(payload)
    elif dry_run:
        _print_plan(result)
    else:
        _print_score(result)


def register(app: typer.Typer) -> None:
    app.command("play")(play)
