"""Command `discover`: name the physical effect a model is missing, show the gap shrink."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from pianobot.analysis.discover.decide import percent_text
from pianobot.analysis.discover.result import DiscoveryResult
from pianobot.analysis.discover.run import discover_runs
from pianobot.cli.common import (
    DEFAULT_DATA,
    Column,
    DataDir,
    JsonFlag,
    NoProgressFlag,
    PressesOption,
    check_vacuum_option,
    command_progress,
    emit_json,
    output_console,
    print_table,
    print_warning,
    say,
    say_written,
    warn_unfinished,
    writable,
)
from pianobot.errors import check_seed
from pianobot.executor import ExecutorSettings
from pianobot.reports.discover_report import build_discover_report, gap_cell

#: discover needs what the runs measured: mocap trajectories, MIDI outcomes, or both.
RecordedRunIds = Annotated[
    list[str], typer.Argument(help="Run ids (or unique prefixes) with mocap and/or MIDI.")
]


def _print(result: DiscoveryResult, report: Path | None, model_out: Path | None) -> None:
    console = output_console()
    for line in result.decision_line.splitlines():
        console.print(f"[bold]{line}[/bold]")
    console.print(f"Verdict: {result.verdict}")
    for finding in result.findings:
        console.print(f"Measured: {finding.text}")
    if result.base_on_bounds:
        print_warning(f"base parameters on a bound (not pinned by the data): {', '.join(result.base_on_bounds)}")
    for note in result.notes:
        console.print(f"[dim]Data: {note}[/dim]")
    for it in result.iterations:
        if not it.verdicts:
            say(f"{it.heading}: held-out gap of the current model {it.gap_before.text()}: at the noise "
                "level, no candidate fitted")
            continue
        rows = []
        rule = result.rule
        for v in it.verdicts[:12]:
            ratio = "∞" if not math.isfinite(v.ratio) else f"{v.ratio:.2g}×"
            rows.append([v.label, f"{v.delta_ic:.1f}", gap_cell(v.gap_after), f"{percent_text(100 * v.shrink, 100 * rule.min_shrink)} % ({ratio})",
                         f"{percent_text(100 * v.consistency, 100 * rule.min_consistency)} %", v.status, "; ".join(v.reasons)])
        print_table(CANDIDATE_COLUMNS, rows,
                    title=f"{it.heading}: held-out gap of the current model {it.gap_before.text()}")
    say(f"{result.n_train} training / {result.n_held_out} held-out keystrokes, {result.seconds:.1f} s")
    if model_out is not None:
        say_written("model", model_out)
    if report is not None:
        say_written("report", report)


CANDIDATE_COLUMNS = (
    Column("candidate"), Column("ΔIC", justify="right"), Column("held-out gap after", justify="right"),
    Column("shrink", 2, justify="right"), Column("consistent", 3, justify="right"), Column("status"),
    Column("why not", 1, wrap=True),
)


def register(app: typer.Typer) -> None:
    """Add `discover` to the app."""

    @app.command()
    def discover(
        runs: RecordedRunIds,
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
            int, typer.Option("--seed", help="Seed of the held-out split.")
        ] = 0,
        vacuum_kpa: Annotated[
            float | None, typer.Option("--vacuum-kpa", help="Vacuum of runs that do not record it (else -40 kPa is assumed, "
                                                   "and said: only where the fit starts depends on it).")
        ] = None,
        presses: PressesOption = None,
        workers: Annotated[int | None, typer.Option(
            "--workers", min=1, help="Processes for the candidate fits (default: the machine's cores; "
                                     "small work stays in this process).")] = None,
        scheduler: Annotated[str | None, typer.Option(
            "--scheduler", help="Dask scheduler address (tcp://HOST:PORT) to run the candidate fits on.")] = None,
        no_progress: NoProgressFlag = False,
    ) -> None:
        """Localise where the model and the measurements disagree, name the missing effect, refit."""
        check_vacuum_option(vacuum_kpa)
        check_seed(seed)
        out = writable(out, "--out")
        if model_out is None and out is not None:
            model_out = out.with_suffix(".model.json")
        model_out = writable(model_out, "--model-out")
        warn_unfinished(runs, data)
        result = discover_runs(runs, data, model, seed=seed, model_out=model_out, vacuum_kpa=vacuum_kpa,
                               schedule=presses, progress=command_progress(json_out, no_progress),
                               executor=ExecutorSettings.resolve(workers=workers, scheduler=scheduler))
        if out is not None:
            build_discover_report(result, out, model_path=model_out)
        if json_out:
            payload = result.to_dict()
            payload["report"] = None if out is None else str(out)
            payload["model_file"] = None if model_out is None else str(model_out)
            emit_json(payload)
        else:
            _print(result, out, model_out)
