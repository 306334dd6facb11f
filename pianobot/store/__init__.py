"""The dataset on disk: run folders with a plan, a journal, Parquet parts and compacted tables.

    from pianobot.store import RunWriter, load_run, list_runs, Run

Layout and columns are fixed in docs/architecture.md; `pianobot.store.schema` holds them.
Names are imported on first use: `pianobot runs` lists runs without loading pyarrow (a fifth
of a second), while writing, repairing and reading tables load it when they start.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from pianobot.store.integrity import Damage, RunHealth, check_run
    from pianobot.store.journal import read_journal
    from pianobot.store.layout import RunDamaged, RunPaths, check_data_dir, resolve_run, runs_dir
    from pianobot.store.lock import LockLost, RunLock, RunLocked, read_holder
    from pianobot.store.reader import (
        Run,
        RunSummary,
        list_runs,
        load_run,
        load_runs,
        rig_summary,
        software_summary,
        summarize_run,
        unfinished_note,
    )
    from pianobot.store.repair import RepairReport, repair_run
    from pianobot.store.schema import SCHEMA_VERSION, TABLE_SCHEMAS, empty_frame
    from pianobot.store.writer import RunWriter, StagedPart, encode_part, stage_part

_HOME = {
    "integrity": ("Damage", "RunHealth", "check_run"),
    "journal": ("read_journal",),
    "layout": ("RunDamaged", "RunPaths", "check_data_dir", "resolve_run", "runs_dir"),
    "lock": ("LockLost", "RunLock", "RunLocked", "read_holder"),
    "reader": ("Run", "RunSummary", "list_runs", "load_run", "load_runs", "rig_summary", "software_summary",
               "summarize_run", "unfinished_note"),
    "repair": ("RepairReport", "repair_run"),
    "schema": ("SCHEMA_VERSION", "TABLE_SCHEMAS", "empty_frame"),
    "writer": ("RunWriter", "StagedPart", "encode_part", "stage_part"),
}
_MODULE_OF = {name: module for module, names in _HOME.items() for name in names}


def __getattr__(name: str) -> Any:
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


__all__ = [
    "SCHEMA_VERSION",
    "TABLE_SCHEMAS",
    "Damage",
    "LockLost",
    "RepairReport",
    "Run",
    "RunDamaged",
    "RunHealth",
    "RunLock",
    "RunLocked",
    "RunPaths",
    "RunSummary",
    "RunWriter",
    "StagedPart",
    "check_data_dir",
    "check_run",
    "empty_frame",
    "encode_part",
    "list_runs",
    "load_run",
    "load_runs",
    "read_holder",
    "read_journal",
    "repair_run",
    "resolve_run",
    "rig_summary",
    "software_summary",
    "runs_dir",
    "stage_part",
    "summarize_run",
    "unfinished_note",
]
