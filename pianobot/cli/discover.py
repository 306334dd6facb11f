"""Command `discover`: name the physical effect a model is missing, show the gap shrink."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from pianobot.analysis.discover import discover_runs
from pianobot.analysis.discover_result import DiscoveryResult
from pianobot.cli.common import (
    DEFAULT_DATA,
    Column,
    DataDir,
    JsonFlag,
    emit_json,
    print_table,
    say_written,
)
from pianobot.reports.discover_report import build_discover_report

RunIds = Annotated[
    list[str], typer.Argument(help="Run ids (or unique prefixes) with mocap and/or MIDI.")
]


def _print(result: DiscoveryResult, report: Path | None, model_out: Path | None) -> None:
    console = Console()
    for line in result.decision_line.splitlines():
        console.print(f"[bold]{line}[/bold]")
    console.print(f"Verdict: {result.verdict}")
    for note in result.notes:
        console.print(f"[dim]Assumed: {note}[/dim]")
    for it in result.iterations:
        rows = [[c.effect, f"{c.delta_bic:.1f}", f"{c.gap_before:.3g}", f"{c.gap_after:.3g}", c.status]
                for c in it.candidates]
        print_table(CANDIDATE_COLUMNS, rows,
                    title=f"Iteration {it.index + 1} (ΔBIC threshold {it.threshold:.1f})")
    if model_out is not None:
        say_written("model", model_out)
    if report is not None:
        say_written("report", report)


CANDIDATE_COLUMNS = (
    Column("effect"), Column("ΔBIC", justify="right"), Column("gap before", justify="right"),
    Column("gap after", justify="right"), Column("status"),
)


def register(app: typer.Typer) -> None:
    """Add `discover` to the app."""

    @app.command()
    def discover(
        runs: RunIds,
        data: DataDir = DEFAULT_DATA,
        json_out: JsonFlag = False,
        model: Annotated[
            str, typer.Option("--model", help="Start model: a model file or 'study'.")
        ] = "study",
        out: Annotated[Path | None, typer.Option("--out", help="HTML report to write.")] = None,
        model_out: Annotated[
            Path | None, typer.Option("--model-out", help="Where to write the updated model file.")
        ] = None,
        seed: Annotated[
            int, typer.Option("--seed", help="Seed of the split and the bootstrap.")
        ] = 0,
        vacuum_kpa: Annotated[
            float | None, typer.Option("--vacuum-kpa", help="Vacuum of runs that do not record it.")
        ] = None,
    ) -> None:
        """Localise where the model and the measurements disagree, name the missing effect, refit."""
        if model_out is None and out is not None:
            model_out = out.with_suffix(".model.json")
        result = discover_runs(
            runs, data, model, seed=seed, model_out=model_out, vacuum_kpa=vacuum_kpa
        )
        if out is not None:
            build_discover_report(result, out, model_path=model_out)
        if json_out:
            payload = result.to_dict()
            payload["report"] = None if out is None else str(out)
            payload["model_file"] = None if model_out is None else str(model_out)
            emit_json(payload)
        else:
            _print(result, out, model_out)
