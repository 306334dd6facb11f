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

from pianobot.cli.common import (
    DEFAULT_DATA,
    Column,
    DataDir,
    JsonFlag,
    emit_json,
    print_fields,
    print_table,
    say,
    say_written,
)
from pianobot.play import PlayResult, play_song

# (column, heading with unit, scale, format, priority): priority 0 always shows, the highest
# number is dropped first on a narrow terminal (`--json` keeps every column).
PLAN_COLUMNS: tuple[tuple[str, str, float, str, int], ...] = (
    ("note_index", "#", 1.0, "d", 0),
    ("pitch", "pitch", 1.0, "d", 0),
    ("onset_s", "onset (s)", 1.0, ".2f", 0),
    ("song_velocity", "song vel.", 1.0, ".0f", 3),
    ("target_velocity", "target vel.", 1.0, ".0f", 0),
    ("vacuum_kpa", "vacuum (kPa)", 1.0, ".0f", 0),
    ("down_velocity_mps", "down (mm/s)", 1e3, ".1f", 0),
    ("hold_s", "hold (ms)", 1e3, ".0f", 2),
    ("predicted_velocity", "predicted vel.", 1.0, ".1f", 1),
    ("predicted_lead_s", "lead (ms)", 1e3, ".0f", 3),
    ("start_s", "motion start (s)", 1.0, ".3f", 2),
    ("move_s", "move (ms)", 1e3, ".0f", 4),
    ("status", "status", 1.0, "", 0),
    ("reason", "reason", 1.0, "", 0),
)


def _fmt(value: Any, scale: float = 1.0, spec: str = ".3g") -> str:
    if isinstance(value, bool) or value is None:
        return "-" if value is None else str(value)
    if isinstance(value, int | float):
        if isinstance(value, float) and math.isnan(value):
            return "-"
        if spec == "d":
            return str(int(value))
        return format(float(value) * scale, spec or ".3g")
    return str(value)


def _print_plan(result: PlayResult) -> None:
    notes = result.plan.notes
    specs = [c for c in PLAN_COLUMNS if c[0] in notes.columns]
    columns = [Column(head, prio, "left" if name in ("status", "reason") else "right",
                      wrap=name == "reason") for name, head, _, _, prio in specs]
    rows = [[_fmt(row[name], scale, spec) for name, _, scale, spec, _ in specs]
            for _, row in notes.iterrows()]
    print_table(columns, rows, title=f"{result.plan.planner} plan of {result.song.source}")
    summary = result.plan.summary()
    geometry = summary["geometry"] or {}
    say(f"mapping: {summary['dynamics']['text'] if summary['dynamics'] else 'none'}; "
        f"{summary['planned']} of {summary['notes']} notes planned, {summary['skipped']} skipped; "
        f"stroke: hover {geometry.get('distance_m', float('nan')) * 1e3:.0f} mm, "
        f"{geometry.get('acceleration_mps2', float('nan')):g} m/s², "
        f"up {geometry.get('up_velocity_mps', float('nan')) * 1e3:.0f} mm/s")


def _print_score(result: PlayResult) -> None:
    assert result.score is not None and result.performance is not None
    fields: list[tuple[str, Any]] = [(key, _fmt(value)) for key, value in result.score.to_dict().items()]
    mapping = result.plan.summary()["dynamics"]
    fields.append(("mapping", mapping["text"] if mapping else "none (velocity → speed)"))
    print_fields(fields, title=f"{result.plan.planner} planner on {result.song.source}")
    say(f"run {result.performance.run_id}: {result.performance.status}")
    for what, path in result.files.items():
        say_written(what, path)


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
