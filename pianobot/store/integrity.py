"""Is a run folder intact? Every file checked against what the journal says was written.

    health = check_run(paths)            # deep: SHA-256 of every file against its record
    health = check_run(paths, deep=False)  # quick (for `pianobot runs`): every file readable
    if not health.ok: print(health.reason)

Damage is what loses or falsifies data: a run.json that does not parse, a plan, part or
compacted table that is truncated, unreadable, missing, or not the bytes (rows, SHA-256) the
journal recorded when it was written. Harmless leftovers of a kill (a batch whose trials part
never landed, a torn last journal line) are notes, not damage: the writer cleans them up.
Files written before the journal kept records (older runs) are checked by reading them whole.
"""

from __future__ import annotations

import json
from collections.abc import Collection
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pianobot.store.footer import ParquetFooter, read_footer
from pianobot.store.layout import TABLE_NAMES, RunPaths, batches_of, read_json, sha256_file
from pianobot.store.records import FileRecord, JournalIndex, index_journal

# What reading a damaged JSON file or Parquet footer can raise (`FooterError` is a ValueError).
# The quick check reads footers without pyarrow, so `pianobot runs` starts without it.
READ_ERRORS: tuple[type[Exception], ...] = (OSError, ValueError, UnicodeDecodeError)


def parquet_errors() -> tuple[type[Exception], ...]:
    """`READ_ERRORS` and pyarrow's own: what reading a damaged Parquet file's pages can raise."""
    import pyarrow as pa

    return (*READ_ERRORS, pa.ArrowException)


@dataclass(frozen=True)
class Damage:
    """One damaged file: which, what is wrong, and what it holds."""

    file: str  # relative to the run folder
    problem: str
    table: str  # run.json | plan | trials | samples | midi
    batch: int | None = None  # the part batch; None for compacted tables, plan, run.json

    def text(self) -> str:
        return f"{self.file} {self.problem}"

    def to_dict(self) -> dict[str, Any]:
        return {"file": self.file, "problem": self.problem, "table": self.table, "batch": self.batch}


@dataclass(frozen=True)
class RunHealth:
    """The outcome of `check_run`."""

    run_id: str
    damage: tuple[Damage, ...]
    notes: tuple[str, ...]
    files_checked: int
    deep: bool
    unrecorded: int = 0  # data files a deep check found no journal record for: read, not verified

    @property
    def ok(self) -> bool:
        return not self.damage

    @property
    def reason(self) -> str:
        """The first problem in one line (`parts/samples-000003.parquet is truncated ...`)."""
        if not self.damage:
            return "intact"
        more = len(self.damage) - 1
        return self.damage[0].text() + (f" (and {more} more damaged file{'s' * (more > 1)})" if more else "")

    def to_dict(self) -> dict[str, Any]:
        return {"run_id": self.run_id, "ok": self.ok, "reason": None if self.ok else self.reason,
                "damage": [d.to_dict() for d in self.damage], "notes": list(self.notes),
                "files_checked": self.files_checked, "deep": self.deep, "unrecorded": self.unrecorded}


@dataclass
class _Check:
    paths: RunPaths
    deep: bool
    index: JournalIndex
    hash_tables: frozenset[str] = frozenset(TABLE_NAMES)
    damage: list[Damage] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    files: int = 0
    unrecorded: int = 0

    def add(self, path: Path, problem: str, table: str, batch: int | None = None) -> None:
        self.damage.append(Damage(self.paths.relative(path), problem, table, batch))


def check_run(
    paths: RunPaths, *, deep: bool = True, hash_tables: Collection[str] = TABLE_NAMES
) -> RunHealth:
    """Check every file of a run folder (see the module docstring). Never raises for damage.

    `hash_tables`: the tables whose parts a deep check hashes (the writer, before it compacts,
    hashes only the parts it merges); the others' parts are checked for rows.
    """
    index = index_journal(paths.journal) if deep else JournalIndex()
    check = _Check(paths, deep, index, frozenset(hash_tables))
    meta = _check_meta(check)
    _check_plan(check, meta)
    held = _check_compacted(check)
    _check_recorded_trials(check, meta)
    _check_parts(check, held)
    if index.garbled_lines:
        shown = ", ".join(str(n) for n in index.garbled_lines[:5])
        check.notes.append(f"journal.jsonl: {len(index.garbled_lines)} garbled line(s) skipped ({shown})")
    if check.unrecorded:
        # Read whole, a file with a flipped byte in a data page still reads: only its SHA-256
        # against the journal's record tells. Say that it could not be checked.
        state = "is missing" if not paths.journal.is_file() else (
            "is empty" if paths.journal.stat().st_size == 0 else "has no record of them (cut short?)")
        check.notes.append(f"journal.jsonl {state}: {check.unrecorded} data file(s) were only read, their bytes "
                           "not checked against what was written")
    return RunHealth(paths.run_id, tuple(check.damage), tuple(check.notes), check.files, deep, check.unrecorded)


def _check_meta(check: _Check) -> dict[str, Any] | None:
    path = check.paths.run_json
    check.files += 1
    try:
        meta = read_json(path)
    except FileNotFoundError:
        check.add(path, "is missing", "run.json")
        return None
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        detail = exc.msg if isinstance(exc, json.JSONDecodeError) else type(exc).__name__
        check.add(path, f"is not readable JSON ({detail})", "run.json")
        return None
    if not isinstance(meta, dict) or not isinstance(meta.get("run_id"), str) or "kind" not in meta:
        check.add(path, "is not a run record (no run_id or kind)", "run.json")
        return None
    return meta


def _check_plan(check: _Check, meta: dict[str, Any] | None) -> None:
    path = check.paths.plan
    planned = meta.get("trials_planned") if meta else None
    if not path.is_file():
        if isinstance(planned, int) and planned > 0:
            check.add(path, "is missing", "plan")
        return
    record = FileRecord.parse(meta.get("plan_file")) if meta else None
    footer = _check_file(check, path, "plan", None, record)
    if footer is not None and isinstance(planned, int) and footer.num_rows != planned:
        check.add(path, f"has {footer.num_rows} rows, run.json plans {planned} trials", "plan")


def _check_compacted(check: _Check) -> dict[str, set[int] | None]:
    """Check the compacted tables; return the batches each one holds (None: damaged)."""
    held: dict[str, set[int] | None] = {name: set() for name in TABLE_NAMES}
    for name in TABLE_NAMES:
        path = check.paths.table(name)
        versions = check.index.compacted.get(name, [])
        if not path.is_file():
            expected = set().union(*(set(r.batches) for r in versions)) if versions else set()
            on_disk = set(check.paths.part_batches()[name])
            lost = expected - on_disk - check.index.lost_batches
            if lost and _recorded_with_rows(check.index, name, lost):
                check.add(path, f"is missing (it held batches {_batches_text(lost)})", name)
            continue
        footer = _check_file(check, path, name, None, None, versions)
        try:
            held[name] = batches_of(footer.metadata) if footer is not None else None
        except (ValueError, UnicodeDecodeError):
            check.add(path, "has unreadable batch metadata", name)
            held[name] = None
    return held


def _check_recorded_trials(check: _Check, meta: dict[str, Any] | None) -> None:
    """Trials run.json counts, with no trials table nor part on disk: lost (the quick check has no
    journal to tell; a deleted trials.parquet listed as 'completed 0/300')."""
    counts = meta.get("trial_counts") if meta else None
    recorded = sum(v for k, v in counts.items() if k != "batch" and isinstance(v, int)) if isinstance(counts, dict) else 0
    path = check.paths.table("trials")
    if recorded and not path.is_file() and not check.paths.part_batches()["trials"] and not any(
            d.table == "trials" for d in check.damage):
        check.add(path, f"is missing (run.json counts {recorded} trials)", "trials")


def _check_parts(check: _Check, held: dict[str, set[int] | None]) -> None:
    parts = check.paths.part_batches()
    committed = set(parts["trials"]) | (held["trials"] or set())
    for name in TABLE_NAMES:
        for batch, path in sorted(parts[name].items()):
            if batch not in committed:
                check.notes.append(f"{check.paths.relative(path)}: batch {batch} never committed "
                                   "(its trials part did not land); the writer removes it")
                continue
            record = check.index.parts.get(batch, {}).get(name)
            _check_file(check, path, name, batch, record)
    # Every batch the journal says landed must still be somewhere (a part or a compacted file).
    for batch, files in sorted(check.index.parts.items()):
        if batch in check.index.lost_batches:
            continue
        for name, record in files.items():
            in_table = held[name]
            if batch in parts[name] or in_table is None or batch in in_table:
                continue  # on disk, or in a compacted file (damaged ones are reported already)
            if record.rows or name == "trials":
                check.add(check.paths.root / record.file, "is missing (journalled as written, "
                          f"{record.rows} rows)", name, batch)


def _check_file(
    check: _Check, path: Path, table: str, batch: int | None, record: FileRecord | None,
    versions: list[FileRecord] | None = None,
) -> ParquetFooter | None:
    """The footer (rows, metadata) of a Parquet file, or None after recording why it is damaged."""
    check.files += 1
    try:
        footer = read_footer(path)
    except FileNotFoundError:
        # Gone since it was listed: a live writer compacted it away. A file that should be
        # there and is not is found from the journal's records instead.
        check.notes.append(f"{check.paths.relative(path)} vanished while being checked (compaction?)")
        return None
    except READ_ERRORS as exc:
        size = _size(path)
        check.add(path, f"is truncated or unreadable ({size:,} bytes: {_why(exc)})", table, batch)
        return None
    rows = footer.num_rows
    known = [record] if record is not None else list(versions or [])
    if known and not any(r.rows == rows for r in known):
        check.add(path, f"has {rows} rows, the journal recorded {known[-1].rows}", table, batch)
        return None
    if not check.deep or (batch is not None and table not in check.hash_tables):
        return footer
    if known:
        digest = sha256_file(path)
        if not any(r.sha256 == digest for r in known):
            check.add(path, f"is not the file that was written (SHA-256 differs; {_size(path):,} "
                      f"bytes, written {known[-1].size:,})", table, batch)
            return None
        return footer
    import pyarrow.parquet as pq

    check.unrecorded += 1
    try:  # no record (written by an older pianobot, or its journal is gone): read every page
        pq.read_table(path)
    except parquet_errors() as exc:
        check.add(path, f"is unreadable ({_why(exc)})", table, batch)
        return None
    return footer


def _recorded_with_rows(index: JournalIndex, name: str, batches: set[int]) -> bool:
    """Whether any of `batches` had rows in table `name` when written (else nothing is lost)."""
    for batch in batches:
        record = index.parts.get(batch, {}).get(name)
        if record is None or record.rows or name == "trials":
            return True
    return False


def _batches_text(batches: set[int]) -> str:
    ordered = sorted(batches)
    return ", ".join(str(b) for b in ordered[:6]) + (", ..." if len(ordered) > 6 else "")


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except OSError:
        return 0


def _why(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= 80 else text[:77] + "..."
