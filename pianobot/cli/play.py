"""Command `play`: play a MIDI song on the rig with the model-based (or naive) planner, score it.

Warnings (chords reduced to a melody, notes that cannot be played in time, clipped loudness)
go to stderr, one line each; the score (or with `--dry-run` the plan) to stdout.
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

PLAN_SHOWN = ("note_index", "pitch", "onset_s", "song_velocity", "target_velocity", "vacuum_kpa",
              "down_velocity_mps", "hold_s", "predicted_velocity", "predicted_lead_s", "start_s",
              "move_s", "status", "reason")


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return "-" if math.isnan(value) else f"{value:.3g}"
    return str(value)


def _print_plan(result: PlayResult) -> None:
    table = Table(title=f"{result.plan.planner} plan of {result.song.source}")
    for column in PLAN_SHOWN:
        table.add_column(column)
    for _, row in result.plan.notes.iterrows():
        table.add_row(*(_fmt(row[c]) for c in PLAN_SHOWN))
    console = Console()
    console.print(table)
    summary = result.plan.summary()
    geometry = summary["geometry"] or {}
    console.print(f"mapping: {summary['dynamics']['text'] if summary['dynamics'] else 'none'}; "
                  f"{summary['planned']} of {summary['notes']} notes planned, {summary['skipped']} skipped; "
                  f"stroke: hover {geometry.get('distance_m', float('nan')) * 1e3:.0f} mm, "
                  f"{geometry.get('acceleration_mps2', float('nan')):g} m/s², up {geometry.get('up_velocity_mps', float('nan')):g} m/s",
                  highlight=False, markup=False)


def _print_score(result: PlayResult) -> None:
    assert result.score is not None and result.performance is not None
    score = result.score.to_dict()
    table = Table(title=f"{result.plan.planner} planner on {result.song.source}")
    table.add_column("measure")
    table.add_column("value", justify="right")
    for key, value in score.items():
        table.add_row(key, _fmt(value))
    mapping = result.plan.summary()["dynamics"]
    table.add_row("mapping", mapping["text"] if mapping else "none (velocity → speed)")
    console = Console()
    console.print(table)
    console.print(f"run {result.performance.run_id}: {result.performance.status}; "
                  f"files: {', '.join(result.files.values())}", highlight=False, markup=False, soft_wrap=True)


def play(
    song: Annotated[Path, typer.Argument(help="A type-0 or type-1 MIDI file.")],
    data: DataDir = DEFAULT_DATA,
    json_out: JsonFlag = False,
    model: Annotated[Path | None, typer.Option("--model", help="Model or predictor file (default: the published physics model).")] = None,
    planner: Annotated[str, typer.Option("--planner", help="model | naive (the study's demo logic).")] = "model",
    adapt: Annotated[bool, typer.Option("--adapt", help="Correct the model online from the piano's MIDI.")] = False,
    dry_run: Annotated[bool, typer.Option("--dry-run", help="Print the plan; do not play.")] = False,
    tempo_scale: Annotated[float, typer.Option("--tempo-scale", help="Multiply the tempo (0.5 = half speed).")] = 1.0,
    transpose: Annotated[int, typer.Option("--transpose", help="Semitones to add to every note.")] = 0,
    track: Annotated[int | None, typer.Option("--track", help="Play only this track (0-based).")] = None,
    dynamics: Annotated[str, typer.Option("--dynamics", help="mapped (song range → reachable range) | absolute (clip).")] = "mapped",
    rig: Annotated[str, typer.Option("--rig", help="sim (the built-in rig: sweep-like moves between keys), or a rig file such as experiments/rigs/sim-play.yaml (a player's moves).")] = "sim",
    seed: Annotated[int | None, typer.Option("--seed", help="Seed of the simulated world.")] = None,
    plot: Annotated[Path | None, typer.Option("--plot", help="Also write the piano roll here (PNG).")] = None,
) -> None:
    """Play a MIDI song with feedforward control from the internal model, and score it."""
    result = play_song(song, data_dir=data, model=model, planner=planner, adapt=adapt, dry_run=dry_run,
                       tempo_scale=tempo_scale, transpose=transpose, track=track, dynamics=dynamics,
                       rig=rig, seed=seed, plot=plot)
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
