"""Commands `sweep` (run or resume a spec on its rig) and `runs` (list and show runs).

Exit codes of `sweep`: 0 completed, 1 failed, 2 bad input, 3 stopped by a safety stop,
130 interrupted (Ctrl-C / SIGTERM). A stopped or interrupted run resumes with `--resume`.
"""

from __future__ import annotations

import math
import shlex
import sys
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.table import Table

from pianobot.cli.common import DEFAULT_DATA, DataDir, JsonFlag, emit_json, print_error
from pianobot.plan import DEFAULT_MAX_TRIALS, format_duration
from pianobot.run import RunOutcome, dry_run, run_sweep
from pianobot.store import (
    RunDamaged,
    RunHealth,
    RunSummary,
    check_run,
    list_runs,
    load_run,
    repair_run,
    rig_summary,
    summarize_run,
)
from pianobot.store.tables import trial_status_counts

EXIT_CODES = {"completed": 0, "failed": 1, "damaged": 1, "stopped": 3, "interrupted": 130}


def _console() -> Console:
    """A console; piped output gets wide lines instead of rich's 80-column default."""
    console = Console()
    return console if console.is_terminal else Console(width=200)


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
    console = _console()
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


def _print_summaries(summaries: list[RunSummary]) -> None:
    table = Table(title=None)
    # The run id is what people copy into the next command: never truncate it.
    table.add_column("run id", no_wrap=True, min_width=max(len(s.run_id) for s in summaries))
    for column in ("name", "kind", "status", "trials", "silent", "lab time"):
        table.add_column(column, justify="right" if column in ("trials", "silent", "lab time") else "left")
    for s in summaries:
        planned = "?" if s.trials_planned is None else str(s.trials_planned)
        silent = "-" if math.isnan(s.silent_pct) else f"{s.silent_pct:.0f}%"
        table.add_row(s.run_id, s.name, s.kind, s.status, f"{s.trials_done}/{planned}", silent, format_duration(s.lab_time_s))
    console = _console()
    console.print(table)
    for s in summaries:
        if s.status == "damaged":
            console.print(f"damaged: {s.run_id}: {s.reason} (`pianobot runs check {s.run_id}`)",
                          highlight=False, markup=False, soft_wrap=True)


def _run_details(run_id: str, data: Path) -> dict[str, Any]:
    run = load_run(run_id, data, check=False)
    health = check_run(run.paths, deep=False)
    if not health.ok:
        raise RunDamaged(health.reason, run.run_id)
    meta = run.meta
    summary = summarize_run(run)
    spec = meta.get("spec", {}) if isinstance(meta.get("spec"), dict) else {}
    return {
        **summary.to_dict(),
        "path": str(run.path),
        "counts": trial_status_counts(run.paths),
        "spec_path": spec.get("path"),
        "spec_sha256": meta.get("spec_sha256"),
        "seed": meta.get("seed"),
        "rig_kind": _rig_kind(meta.get("rig")),
        "rig": rig_summary(meta),
        "pianobot_version": meta.get("pianobot_version"),
        "git_commit": meta.get("git_commit"),
        "end_utc": meta.get("end_utc"),
        "sessions": meta.get("sessions"),
        "interruptions": meta.get("interruptions", []),
        "journal_events": len(run.journal),
        "meta": meta,
    }


def _rig_kind(rig: Any) -> str | None:
    """The rig kind recorded by a sweep (`rig.spec.kind`); importers may record other shapes."""
    if isinstance(rig, dict):
        spec = rig.get("spec")
        if isinstance(spec, dict) and spec.get("kind"):
            return str(spec["kind"])
        if rig.get("kind"):
            return str(rig["kind"])
    return None if rig is None else str(rig)


def _print_details(details: dict[str, Any]) -> None:
    console = _console()
    table = Table(show_header=False, box=None)
    table.add_column(style="bold")
    table.add_column()
    counts = details["counts"]
    rows = [
        ("run id", details["run_id"]),
        ("name / kind", f"{details['name']} / {details['kind']}"),
        ("status", details["status"] + (f" — {details['reason']}" if details["reason"] else "")),
        ("trials", f"{details['trials_done']}/{details['trials_planned']} done: {counts['ok']} ok, "
                   f"{counts['silent']} silent, {counts['failed']} failed"),
        ("lab time", format_duration(details["lab_time_s"])),
        ("started / ended", f"{details['start_utc']} / {details['end_utc'] or '-'}"),
        ("spec", f"{details['spec_path']} (sha256 {str(details['spec_sha256'])[:12]})"),
        ("rig / seed", f"{details['rig']} / {details['seed']}"),
        ("pianobot / git", f"{details['pianobot_version']} / {details['git_commit'] or '-'}"),
        ("folder", details["path"]),
    ]
    for item in details["interruptions"]:
        rows.append(("interruption", f"{item.get('t_utc')}: {item.get('kind')} — {item.get('reason')}"))
    for key, value in rows:
        table.add_row(key, str(value))
    console.print(table, highlight=False)


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
        batch_trials: Annotated[int, typer.Option(
            "--batch-trials", min=1,
            help="Trials per Parquet part (also flushed every 2 s); a crash loses at most one batch.",
        )] = 50,
    ) -> None:
        """Run an experiment spec on its rig into data/runs/<run_id>/ (or --dry-run it)."""
        if dry_run_flag:
            if spec is None:
                raise typer.BadParameter("--dry-run needs a SPEC")
            summary = dry_run(spec, rig_path=rig, max_trials=max_trials)
            if json_out:
                emit_json(summary.to_dict())
            else:
                print(summary.to_text())
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
        )
        if json_out:
            emit_json(outcome.to_dict())
        else:
            _print_outcome(outcome, data, spec)
        raise typer.Exit(code=EXIT_CODES.get(outcome.status, 1))

    runs_app = typer.Typer(help="List runs; show, check or repair one run.", no_args_is_help=False)

    @runs_app.callback(invoke_without_command=True)
    def runs(ctx: typer.Context, data: DataDir = DEFAULT_DATA, json_out: JsonFlag = False) -> None:
        """List the runs in DATA/runs: id, name, status, trials done/planned, silent %, lab time."""
        if ctx.invoked_subcommand is not None:
            return
        summaries = list_runs(data)
        if json_out:
            emit_json([s.to_dict() for s in summaries])
        elif not summaries:
            print(f"no runs in {data}/runs yet; start one with `pianobot sweep SPEC --data {data}`")
        else:
            _print_summaries(summaries)

    @runs_app.command("show")
    def show(
        run_id: Annotated[str, typer.Argument(help="Run id or a unique prefix.")],
        data: DataDir = DEFAULT_DATA,
        json_out: JsonFlag = False,
    ) -> None:
        """Show one run: status and reason, trial counts, spec, seed, versions, interruptions."""
        details = _run_details(run_id, data)
        if json_out:
            emit_json(details)
        else:
            _print_details(details)

    @runs_app.command("check")
    def check(
        run_id: Annotated[str, typer.Argument(help="Run id or a unique prefix.")],
        data: DataDir = DEFAULT_DATA,
        json_out: JsonFlag = False,
    ) -> None:
        """Verify every file of a run against its journal (readable, rows, SHA-256). Exit 1 if damaged."""
        health = check_run(load_run(run_id, data, check=False).paths, deep=True)
        if json_out:
            emit_json(health.to_dict())
        else:
            _print_health(health)
        raise typer.Exit(code=0 if health.ok else 1)

    @runs_app.command("repair")
    def repair(
        run_id: Annotated[str, typer.Argument(help="Run id or a unique prefix.")],
        data: DataDir = DEFAULT_DATA,
        json_out: JsonFlag = False,
    ) -> None:
        """Repair a damaged run: restore from the journal, quarantine the rest, mark lost trials to redo."""
        report = repair_run(load_run(run_id, data, check=False).paths)
        if json_out:
            emit_json(report.to_dict())
        else:
            for line in report.lines():
                print(line)
        raise typer.Exit(code=0 if report.ok else 1)

    app.add_typer(runs_app, name="runs")


def _print_health(health: RunHealth) -> None:
    if health.ok:
        print(f"run {health.run_id}: intact ({health.files_checked} files checked against the journal)")
    else:
        print(f"run {health.run_id}: DAMAGED ({len(health.damage)} of {health.files_checked} files)")
        for damage in health.damage:
            print(f"  {damage.text()}")
        print(f"repair: pianobot runs repair {health.run_id}")
    for note in health.notes:
        print(f"  note: {note}")
