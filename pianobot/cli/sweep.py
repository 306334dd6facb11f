"""Command `sweep`: run or resume a spec on its rig (or dry-run it).

Exit codes of `sweep`: 0 completed, 1 failed, 2 bad input, 3 stopped by a safety stop,
130 interrupted (Ctrl-C / SIGTERM). A stopped or interrupted run resumes with `--resume`.
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from pianobot.cli.common import (
    DEFAULT_DATA,
    DataDir,
    JsonFlag,
    emit_json,
    output_console,
    print_error,
    say,
)
from pianobot.durations import format_duration
from pianobot.errors import InputError, check_seed
from pianobot.executor import ENV_SCHEDULER, ENV_WORKERS, ExecutorSettings
from pianobot.plan.size import DEFAULT_MAX_TRIALS
from pianobot.run import RunOutcome, RunStarted, dry_run, run_sweep

EXIT_CODES = {"completed": 0, "failed": 1, "damaged": 1, "stopped": 3, "interrupted": 130}


def _how_to_look(outcome: RunOutcome, data: Path, spec: Path | None) -> list[str]:
    run_id, data_arg = outcome.run_id, shlex.quote(str(data))
    lines = [
        f"data: {outcome.path}",
        f"  pianobot runs show {run_id} --data {data_arg}",
        f"  python -c \"from pianobot.store import load_run; print(load_run('{run_id}', '{data}').trials)\"",
    ]
    if outcome.status in ("stopped", "interrupted", "failed"):
        spec_arg = f"{shlex.quote(str(spec))} " if spec is not None else ""
        lines.append(f"resume: pianobot sweep {spec_arg}--resume {run_id} --data {data_arg}")
    return lines


def _print_outcome(outcome: RunOutcome, data: Path, spec: Path | None) -> None:
    console = output_console()
    style = {"completed": "green", "stopped": "yellow", "interrupted": "yellow"}.get(outcome.status, "red")
    console.print(
        f"run [bold]{outcome.run_id}[/]: [{style}]{outcome.status}[/] — "
        f"{outcome.trials}/{outcome.planned} trials ({outcome.silent} silent, {outcome.failed} failed, "
        f"{outcome.retries} retries this session), lab time {format_duration(outcome.lab_time_s)}",
        highlight=False,
    )
    if outcome.reason:
        console.print(f"reason: {outcome.reason}", highlight=False, markup=False)
    for line in _how_to_look(outcome, data, spec):
        console.print(line, highlight=False, markup=False, soft_wrap=True)


def _warn_before_motion(record: Any) -> None:
    """The rig's warnings (e.g. the UR's speed slider below 100 %), on stderr before any motion."""
    if isinstance(record, RunStarted):
        for warning in record.warnings:
            print(f"warning: {warning}", file=sys.stderr, flush=True)


def register(app: typer.Typer) -> None:
    """Add `sweep` and the `runs` group to the app."""

    @app.command()
    def sweep(
        spec: Annotated[Path | None, typer.Argument(help="Experiment spec (YAML). Optional with --resume.")] = None,
        dry_run_flag: Annotated[bool, typer.Option("--dry-run", help="Show the plan and its violations; move nothing.")] = False,
        resume: Annotated[str | None, typer.Option("--resume", help="Continue run RUN_ID (or a unique prefix).")] = None,
        data: DataDir = DEFAULT_DATA,
        json_out: JsonFlag = False,
        seed: Annotated[int | None, typer.Option("--seed", help="Seed of the simulated world (overrides the rig file).")] = None,
        rig: Annotated[Path | None, typer.Option("--rig", help="Rig file to use instead of the spec's.")] = None,
        rig_override: Annotated[bool, typer.Option(
            "--rig-override", help="Resume on another rig than the run started with (recorded per session).",
        )] = False,
        max_trials: Annotated[int, typer.Option(
            "--max-trials", min=1, help="Refuse plans with more trials than this (checked before the plan is built).",
        )] = DEFAULT_MAX_TRIALS,
        no_progress: Annotated[bool, typer.Option("--no-progress", help="No progress bar.")] = False,
        batch_trials: Annotated[int | None, typer.Option(
            "--batch-trials", min=1,
            help="Trials per Parquet part (also flushed every 2 s); a crash loses at most one batch. "
            "Default 50; on the simulated rig 128, simulated together as one block.",
        )] = None,
        workers: Annotated[int | None, typer.Option(
            "--workers", min=1,
            help="Processes for a simulated sweep (default: the machine's cores for big sweeps, "
            f"this process for small ones; env {ENV_WORKERS}, config file [executor] workers).",
        )] = None,
        scheduler: Annotated[str | None, typer.Option(
            "--scheduler", metavar="tcp://HOST:PORT",
            help=f"Run a simulated sweep's blocks on this Dask cluster (env {ENV_SCHEDULER}, "
            "config file [executor] scheduler). This process keeps the run and writes it.",
        )] = None,
    ) -> None:
        """Run an experiment spec on its rig into data/runs/<run_id>/ (or --dry-run it)."""
        if dry_run_flag:
            if spec is None:
                raise typer.BadParameter("--dry-run needs a SPEC")
            if resume is not None:
                raise InputError("a dry run plans a new run; to see what a resume does, leave out --dry-run",
                                 "--resume")
            check_seed(seed)  # as the sweep itself would: a dry run must not pass what the run refuses
            summary = dry_run(spec, rig_path=rig, max_trials=max_trials)
            if json_out:
                emit_json(summary.to_dict())
            else:
                for line in summary.to_text().splitlines():
                    say(line)  # wrapped to the terminal; the spec's own units (as in the YAML)
            errors = [v for v in summary.violations if v.severity == "error"]
            if errors:
                first = errors[0]
                more = f" ({len(errors) - 1} more)" if len(errors) > 1 else ""
                print_error(f"{spec}: trial {first.index} ({first.parameter}): {first.message}{more}")
                raise typer.Exit(code=2)
            return
        outcome = run_sweep(
            spec, data_dir=data, resume=resume, seed=seed, rig_path=rig,
            progress=not no_progress and not json_out and sys.stderr.isatty(), batch_trials=batch_trials,
            max_trials=max_trials, rig_override=rig_override,
            executor=ExecutorSettings.resolve(workers=workers, scheduler=scheduler),
            subscribers=[_warn_before_motion],
        )
        if json_out:
            emit_json(outcome.to_dict())
        else:
            _print_outcome(outcome, data, spec)
        raise typer.Exit(code=EXIT_CODES.get(outcome.status, 1))
