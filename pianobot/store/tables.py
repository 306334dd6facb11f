"""Reading a run's tables from its compacted files and its committed parts, live or finished."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from pianobot.store.layout import TABLE_NAMES, RunDamaged, RunPaths, committed_batches
from pianobot.store.schema import TABLE_SCHEMAS, as_declared, batches_of, with_metadata

# What reading a damaged Parquet file raises.
_READ_ERRORS = (OSError, ValueError, pa.ArrowException)


def _damaged(paths: RunPaths, path: Path, exc: BaseException) -> RunDamaged:
    why = " ".join(str(exc).split())[:80] or type(exc).__name__
    return RunDamaged(f"{paths.relative(path)} is unreadable ({why})", paths.run_id)


def drop_orphan_parts(paths: RunPaths) -> list[Path]:
    """Remove what a killed writer left half-done: temp files, and samples/midi parts of a batch
    whose trials part never landed (nor is in a compacted trials file).

    Only the run's writer calls this (it holds the run lock, so no temp file is still being
    written); readers simply skip such files.
    """
    removed: list[Path] = []
    for folder in (paths.root, paths.parts, paths.samples):
        for temp in folder.glob(".*.tmp"):
            temp.unlink(missing_ok=True)
            removed.append(temp)
    parts = paths.part_batches()
    committed = committed_batches(paths, parts)
    for name in ("samples", "midi"):
        for batch, path in parts[name].items():
            if batch not in committed:
                path.unlink(missing_ok=True)
                removed.append(path)
    return removed


def read_run_table(paths: RunPaths, name: str, columns: list[str] | None = None) -> pa.Table:
    """Table `name` of a run: the compacted file plus every committed part it does not hold.

    Safe while the writer is running or was killed: parts appear by atomic rename, a part batch
    counts only once its trials part exists (or trials.parquet holds it), and batches already
    compacted are not read twice. A finished run's samples are its samples parts, as written.

    Raises:
        RunDamaged: a file is truncated or unreadable (one line naming it and the repair).
    """
    try:
        return _read_run_table(paths, name, columns)
    except RunDamaged:
        raise
    except _READ_ERRORS as exc:
        bad = getattr(exc, "filename", None)
        where = Path(bad) if bad else paths.root
        raise RunDamaged(f"{paths.relative(where) if bad else 'a table'} is unreadable "
                         f"({' '.join(str(exc).split())[:80]})", paths.run_id) from None


def _read_run_table(paths: RunPaths, name: str, columns: list[str] | None) -> pa.Table:
    if name not in TABLE_NAMES:
        raise ValueError(f"table must be one of {TABLE_NAMES}, got {name!r}")
    parts = paths.part_batches()
    # Samples parts outlive their trials parts (compaction merges only trials and midi).
    committed = committed_batches(paths, parts) if name != "trials" else set(parts["trials"])
    tables: list[pa.Table] = []
    held: set[int] = set()
    compacted = paths.table(name)
    if compacted.is_file():
        # One open file for both metadata and rows: a concurrent compaction replaces the file
        # by rename, and this handle keeps reading the version whose batch list we hold.
        try:
            with pq.ParquetFile(compacted) as parquet:
                held = batches_of(parquet.schema_arrow.metadata)
                tables.append(as_declared(parquet.read(columns=columns), name))
        except FileNotFoundError:
            return _read_run_table(paths, name, columns)
        except _READ_ERRORS as exc:
            raise _damaged(paths, compacted, exc) from None
    for batch in sorted(parts[name]):
        if batch in committed and batch not in held:
            try:
                tables.append(as_declared(pq.read_table(parts[name][batch], columns=columns), name))
            except FileNotFoundError:
                # Compaction removed the part after we listed it; it is in the compacted file.
                return _read_run_table(paths, name, columns)
            except _READ_ERRORS as exc:
                raise _damaged(paths, parts[name][batch], exc) from None
    if not tables:
        empty = TABLE_SCHEMAS[name].empty_table()
        if columns is not None:
            empty = empty.select([c for c in columns if c in empty.column_names])
        return with_metadata(empty, name)
    try:
        merged = pa.concat_tables(tables, promote_options="default") if len(tables) > 1 else tables[0]
    except pa.ArrowException as exc:
        raise RunDamaged(f"the {name} files do not fit together ({' '.join(str(exc).split())[:80]})",
                         paths.run_id) from None
    if name == "trials":
        merged = dedupe_trials(merged)
    return with_metadata(merged, name)


def dedupe_trials(table: pa.Table) -> pa.Table:
    """Keep the last row of each trial_id (a trial that failed and was redone on resume).

    Rows are in batch order, so "last" is the most recent attempt. The earlier failure stays in
    the journal.
    """
    if table.num_rows == 0 or "trial_id" not in table.column_names:
        return table
    ids = table.column("trial_id").to_pylist()
    last: dict[str, int] = {}
    for row, trial_id in enumerate(ids):
        last[trial_id] = row
    if len(last) == len(ids):
        return table
    keep = sorted(last.values())
    return table.take(pa.array(keep, type=pa.int64()))


def trial_status_counts(paths: RunPaths) -> dict[str, int]:
    """How many trials of a run ended ok, silent or failed (reads two columns only)."""
    table = read_run_table(paths, "trials", columns=["trial_id", "status"])
    counts: dict[str, int] = {"ok": 0, "silent": 0, "failed": 0}
    if table.num_rows:
        for entry in pc.value_counts(table.column("status")).to_pylist():
            counts[str(entry["values"])] = int(entry["counts"])
    return counts
