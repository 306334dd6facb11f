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
from rich.console import Console
from rich.table import Table

from pianobot.cli.common import DEFAULT_DATA, DataDir, JsonFlag, emit_json
from pianobot.play import PlayResult, play_song
from pianobot.play.warmup import WarmUpFailed
from pianobot.progress import progress_display

# The dry run's table: what a note asks, the stroke chosen, when it starts, how fast the song
# could go for it; everything else is in `--json` (plan_notes).
PLAN_SHOWN = {"note_index": "note", "pitch": "pitch", "onset_s": "onset s", "target_velocity": "target",
              "down_velocity_mps": "speed m/s", "predicted_lead_s": "lead s", "start_s": "start s",
              "tempo_limit_bpm": "limit bpm", "status": "status", "reason": "reason"}


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return "-" if math.isnan(value) else f"{value:.3g}"
    return str(value)


def _tempo_line(result: PlayResult) -> str:
    tempo = result.plan.tempo
    if tempo is None:
        return ""
    feasible = "unknown (no model)" if math.isnan(tempo.feasible_bpm) else (
        "unbounded" if math.isinf(tempo.feasible_bpm) else f"{tempo.feasible_bpm:.4g} bpm")
    limiting = ", ".join(str(i) for i in tempo.limiting_notes) or "-"
    return (f"tempo: written {tempo.written_bpm:.4g} bpm, fastest feasible {feasible} "
            f"(limiting notes: {limiting}), playing at {tempo.played_bpm:.4g} bpm ({tempo.request.describe()})")


def _print_plan(result: PlayResult) -> None:
    table = Table(title=f"{result.plan.planner} plan of {result.song.source}")
    for header in PLAN_SHOWN.values():
        table.add_column(header)
    for row in result.plan.notes[list(PLAN_SHOWN)].itertuples(index=False):
        table.add_row(*(_fmt(v) for v in row))
    console = Console()
    console.print(table)
    summary = result.plan.summary()
    geometry = summary["geometry"] or {}
    console.print(f"mapping: {summary['dynamics']['text'] if summary['dynamics'] else 'none'}; "
                  f"{summary['planned']} of {summary['notes']} notes planned, {summary['skipped']} skipped; "
                  f"stroke: hover {geometry.get('distance_m', float('nan')) * 1e3:.0f} mm, "
                  f"{geometry.get('acceleration_mps2', float('nan')):g} m/s², up {geometry.get('up_velocity_mps', float('nan')):g} m/s",
                  highlight=False, markup=False)
    console.print(_tempo_line(result), highlight=False, markup=False, soft_wrap=True)


def _print_score(result: PlayResult) -> None:
    assert result.score is not None and result.performance is not None
    score = result.score.to_dict()
    table = Table(title=f"{result.plan.planner} planner on {result.song.source}")
    table.add_column("measure")
    table.add_column("value", justify="right")
    for key, value in score.items():
        if isinstance(value, dict):
            for sub, inner in value.items():
                table.add_row(f"{key}.{sub}", _fmt(inner))
        else:
            table.add_row(key, _fmt(value))
    mapping = result.plan.summary()["dynamics"]
    table.add_row("mapping", mapping["text"] if mapping else "none (velocity → speed)")
    console = Console()
    console.print(table)
    if result.warmup is not None:
        w = result.warmup.summary()
        console.print(f"warm-up: {w['strokes']} keystrokes ({w['sounded']} sounded) in {w['lab_time_s']:.1f} s "
                      f"of lab time; fit on strokes held out: velocity MAE "
                      f"{w.get('velocity_mae_held_out', float('nan')):.2f}, lead RMSE "
                      f"{w.get('lead_rmse_ms_held_out', float('nan')):.1f} ms",
                      highlight=False, markup=False)
    console.print(_tempo_line(result), highlight=False, markup=False, soft_wrap=True)
    console.print(f"run {result.performance.run_id}: {result.performance.status}; "
                  f"files: {', '.join(result.files.values())}", highlight=False, markup=False, soft_wrap=True)


def play(
    song: Annotated[Path, typer.Argument(help="A type-0 or type-1 MIDI file.")],
    data: DataDir = DEFAULT_DATA,
    json_out: JsonFlag = False,
    model: Annotated[Path | None, typer.Option("--model", help="Model or predictor file to start from (default: the published physics model).")] = None,
    planner: Annotated[str, typer.Option("--planner", help="model | naive (the study's demo logic).")] = "model",
    adapt: Annotated[bool, typer.Option("--adapt", help="Keep correcting the model from the piano's MIDI during the song.")] = False,
    dry_run: Annotated[bool, typer.Option("--dry-run", help="Print the plan, the fastest feasible tempo and the notes that limit it; move nothing.")] = False,
    tempo: Annotated[str | None, typer.Option("--tempo", help="auto (default: the fastest tempo at which every note can be struck in time, never above the written one) | written (skips what cannot keep up) | beats per minute.")] = None,
    tempo_scale: Annotated[float, typer.Option("--tempo-scale", help="Multiply the written tempo (0.5 = half speed); alone, plays at that tempo.")] = 1.0,
    warmup: Annotated[int | None, typer.Option("--warmup", help="Warm-up keystrokes per vacuum level before the song (default 12).")] = None,
    no_warmup: Annotated[bool, typer.Option("--no-warmup", help="Play with the starting model as it is.")] = False,
    finger: Annotated[str | None, typer.Option("--finger", help="soft (default) | rigid: the safety envelope and stroke defaults.")] = None,
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
    try:
        result = play_song(song, data_dir=data, model=model, planner=planner, adapt=adapt, dry_run=dry_run,
                           tempo=tempo, tempo_scale=tempo_scale, transpose=transpose, track=track,
                           dynamics=dynamics, rig=rig, finger=finger, warmup=0 if no_warmup else warmup, seed=seed,
                           plot=plot, progress=progress_display(not json_out))
    except WarmUpFailed as exc:  # the run is stored (status failed) with the warm-up's keystrokes
        print(f"error: warm-up: {exc}", file=sys.stderr)
        raise typer.Exit(1) from None
    for line in result.warnings:
        print(f"warning: {line}", file=sys.stderr)
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
