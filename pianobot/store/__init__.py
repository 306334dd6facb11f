"""The dataset on disk: run folders with a plan, a journal, Parquet parts and compacted tables.

    from pianobot.store import RunWriter, load_run, list_runs, Run

Layout and columns are fixed in docs/architecture.md; `pianobot.store.schema` holds them.
"""

from __future__ import annotations

from pianobot.store.integrity import Damage, RunHealth, check_run
from pianobot.store.journal import read_journal
from pianobot.store.layout import RunDamaged, RunPaths, check_data_dir, resolve_run, runs_dir
from pianobot.store.lock import LockLost, RunLock, RunLocked, read_holder
from pianobot.store.reader import Run, RunSummary, list_runs, load_run, rig_summary, summarize_run
from pianobot.store.repair import RepairReport, repair_run
from pianobot.store.schema import SCHEMA_VERSION, TABLE_SCHEMAS, empty_frame
from pianobot.store.writer import RunWriter, encode_part

__all__ = [
    "Damage",
    "RepairReport",
    "RunDamaged",
    "RunHealth",
    "SCHEMA_VERSION",
    "TABLE_SCHEMAS",
    "Run",
    "LockLost",
    "RunLock",
    "RunLocked",
    "RunPaths",
    "RunSummary",
    "RunWriter",
    "check_data_dir",
    "check_run",
    "encode_part",
    "empty_frame",
    "list_runs",
    "load_run",
    "read_holder",
    "read_journal",
    "repair_run",
    "resolve_run",
    "rig_summary",
    "runs_dir",
    "summarize_run",
]
