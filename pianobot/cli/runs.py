"""Command `runs`: list the runs of a data folder; show, check or repair one.

Imports only the store (no physics, no plan), so it answers quickly.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import typer

from pianobot.cli.common import (
    DEFAULT_DATA,
    Column,
    DataDir,
    JsonFlag,
    RunId,
    emit_json,
    print_fields,
    print_table,
)
from pianobot.durations import format_duration
from pianobot.store import (
    RunDamaged,
    RunHealth,
    RunSummary,
    check_run,
    list_runs,
    load_run,
    rig_summary,
    software_summary,
    summarize_run,
)
from pianobot.store.reader import trial_counts

RUN_COLUMNS = (
    Column("run id"),  # what people copy into the next command: never cut
    Column("name", 2, wrap=True),
    Column("kind", 3),
    Column("status"),
    Column("trials", justify="right"),
    Column("silent", 1, "right"),
    Column("lab time", 1, "right"),
)


def _print_summaries(summaries: list[RunSummary]) -> None:
    rows = []
    for s in summaries:
        planned = "?" if s.trials_planned is None else str(s.trials_planned)
        silent = "-" if math.isnan(s.silent_pct) else f"{s.silent_pct:.0f}%"
        rows.append([s.run_id, s.name, s.kind, s.status, f"{s.trials_done}/{planned}", silent,
                     format_duration(s.lab_time_s)])
    print_table(RUN_COLUMNS, rows)
    for s in summaries:
        if s.status == "damaged":
            print(f"damaged: {s.run_id}: {s.reason} (`pianobot runs check {s.run_id}`)")


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
        "counts": trial_counts(run, meta),
        "spec_path": spec.get("path"),
        "spec_sha256": meta.get("spec_sha256"),
        "seed": meta.get("seed"),
        "rig_kind": _rig_kind(meta.get("rig")),
        "rig": rig_summary(meta),
        "pianobot_version": meta.get("pianobot_version"),
        "git_commit": meta.get("git_commit"),
        "software_sessions": meta.get("software_sessions"),
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
    counts = details["counts"]
    rows: list[tuple[str, Any]] = [
        ("run id", details["run_id"]),
        ("name / kind", f"{details['name']} / {details['kind']}"),
        ("status", details["status"] + (f" — {details['reason']}" if details["reason"] else "")),
        ("trials", f"{details['trials_done']}/{details['trials_planned']} done: {counts['ok']} ok, "
                   f"{counts['silent']} silent, {counts['failed']} failed"),
        ("lab time", format_duration(details["lab_time_s"])),
        ("started / ended", f"{details['start_utc']} / {details['end_utc'] or '-'}"),
        ("spec", f"{details['spec_path']} (sha256 {str(details['spec_sha256'])[:12]})"),
        ("rig / seed", f"{details['rig']} / {details['seed']}"),
        ("software", software_summary(details["meta"])),
        ("folder", details["path"]),
    ]
    for item in details["interruptions"]:
        rows.append(("interruption", f"{item.get('t_utc')}: {item.get('kind')} — {item.get('reason')}"))
    print_fields(rows)


def register(app: typer.Typer) -> None:
    """Add `runs`, `runs show`, `runs check` and `runs repair` to the app."""
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
        run_id: RunId,
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
        run_id: RunId,
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
        run_id: RunId,
        data: DataDir = DEFAULT_DATA,
        json_out: JsonFlag = False,
    ) -> None:
        """Repair a damaged run: restore from the journal, quarantine the rest, mark lost trials to redo."""
        from pianobot.store import repair_run  # loads pyarrow: only when repairing

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
        if health.unrecorded:
            print(f"run {health.run_id}: readable, not verified ({health.unrecorded} of {health.files_checked} "
                  "files have no journal record to check their bytes against)")
        else:
            print(f"run {health.run_id}: intact ({health.files_checked} files checked against the journal)")
    else:
        print(f"run {health.run_id}: DAMAGED ({len(health.damage)} of {health.files_checked} files)")
        for damage in health.damage:
            print(f"  {damage.text()}")
        print(f"repair: pianobot runs repair {health.run_id}")
    for note in health.notes:
        print(f"  note: {note}")
