"""RunWriter: creates a run folder and writes its plan, parts, journal and compacted tables."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pyarrow as pa
import pyarrow.parquet as pq

import pianobot
from pianobot.store.journal import Journal
from pianobot.store.layout import (
    TABLE_NAMES,
    RunPaths,
    encode_parquet,
    git_commit,
    new_run_id,
    parquet_options,
    read_json,
    resolve_run,
    runs_dir,
    utc_now,
    write_bytes_atomic,
    write_json_atomic,
    write_parquet_atomic,
)
from pianobot.store.lock import RunLock, RunLocked  # noqa: F401  (re-exported: RunLocked used to live here)
from pianobot.store.schema import (
    RUN_KINDS,
    RUN_STATUSES,
    SCHEMA_VERSION,
    TABLE_SCHEMAS,
    batches_of,
    to_table,
    with_metadata,
)
from pianobot.store.tables import committed_batches, dedupe_trials, drop_orphan_parts

if TYPE_CHECKING:  # pandas takes a third of a second to import: only where frames are made
    import pandas as pd


class RunWriter:
    """The one writer of a run folder.

    Create with `RunWriter.create(...)` (a new run) or `RunWriter.reopen(...)` (resume). Each
    `append` writes one batch of parts atomically; `journal` appends an fsync'd line; `finish`
    compacts the parts into one file per table and records the final status in run.json.
    """

    def __init__(self, paths: RunPaths, *, fsync: bool = True) -> None:
        self.paths = paths
        self._lock = RunLock(paths.lock, purpose="writer").acquire()
        try:
            self._journal = Journal(paths.journal, fsync=fsync)
            self._meta = read_json(paths.run_json)
        except BaseException:
            self._lock.release()
            raise
        known = committed_batches(paths)
        self._next_batch = max(known, default=0) + 1

    @property
    def run_id(self) -> str:
        return self.paths.run_id

    @property
    def path(self) -> Path:
        return self.paths.root

    @property
    def meta(self) -> dict[str, Any]:
        """A copy of run.json as last written."""
        return dict(self._meta)

    @classmethod
    def create(
        cls,
        data_dir: Path,
        *,
        name: str,
        kind: str,
        meta: dict[str, Any],
        plan: pd.DataFrame | None,
        fsync: bool = True,
    ) -> RunWriter:
        """Make a new run folder with run.json (status running) and plan.parquet.

        `meta` is merged into run.json (spec, spec_sha256, rig, seed, ...); the writer adds the
        run id, name, kind, status, pianobot version, git commit and start time.
        """
        if kind not in RUN_KINDS:
            raise ValueError(f"run kind must be one of {RUN_KINDS}, got {kind!r}")
        base = runs_dir(data_dir)
        base.mkdir(parents=True, exist_ok=True)
        for _ in range(20):
            root = base / new_run_id(name)
            try:
                root.mkdir()
                break
            except FileExistsError:
                continue
        else:
            raise FileExistsError(f"could not find a free run id in {base}")
        paths = RunPaths(root)
        paths.parts.mkdir()
        now = utc_now()
        record: dict[str, Any] = {
            "run_id": paths.run_id,
            "name": name,
            "kind": kind,
            "status": "running",
            "reason": None,
            "schema_version": SCHEMA_VERSION,
            "pianobot_version": pianobot.__version__,
            "git_commit": git_commit(),
            "created_utc": now,
            "start_utc": now,
            "end_utc": None,
            "trials_planned": None if plan is None else len(plan),
            "interruptions": [],
            **meta,
        }
        if plan is not None:
            table = pa.Table.from_pandas(plan, preserve_index=False)
            write_parquet_atomic(paths.plan, with_metadata(table, "plan"))
        write_json_atomic(paths.run_json, record)
        return cls(paths, fsync=fsync)

    @classmethod
    def reopen(cls, data_dir: Path, run_id: str, *, fsync: bool = True) -> RunWriter:
        """Open an existing run to append to it (resume); parts of an unfinished batch are removed.

        Raises:
            InputError: unknown run id.
            RunLocked: another live process holds the run.
        """
        paths = resolve_run(data_dir, run_id)
        writer = cls(paths, fsync=fsync)
        drop_orphan_parts(paths)
        return writer

    def append(
        self,
        trials: pd.DataFrame | pa.Table,
        samples: pd.DataFrame | pa.Table | None = None,
        midi: pd.DataFrame | pa.Table | None = None,
    ) -> int:
        """Write one batch: a samples part, a midi part, then the trials part that commits it.

        Returns the batch number. Each file is written under a temporary name, fsync'd and
        renamed, so a reader or a kill sees a whole part or none.
        """
        tables = {
            "samples": None if samples is None else to_table(samples, "samples", self.run_id),
            "midi": None if midi is None else to_table(midi, "midi", self.run_id),
            "trials": to_table(trials, "trials", self.run_id),
        }
        self._lock.verify()
        batch = self._next_batch
        for name, table in tables.items():  # trials last: it commits the batch
            if table is not None and (table.num_rows or name == "trials"):
                write_parquet_atomic(self.paths.part(name, batch), with_metadata(table, name))
        self._next_batch += 1
        return batch

    def append_encoded(self, parts: dict[str, bytes]) -> int:
        """Write one batch that was encoded elsewhere (`encode_part`): the same order and
        atomicity as `append` (samples, midi, then the trials part that commits the batch)."""
        if "trials" not in parts:
            raise ValueError("an encoded batch needs its trials part")
        self._lock.verify()  # the run is still ours (a parallel sweep's driver holds the lock)
        batch = self._next_batch
        for name in ("samples", "midi", "trials"):
            if name in parts:
                write_bytes_atomic(self.paths.part(name, batch), parts[name])
        self._next_batch += 1
        return batch

    def journal(self, event: str, **fields: Any) -> None:
        """Append one event to journal.jsonl (fsync'd)."""
        self._journal.write(event, fields)

    def journal_deferred(self, event: str, **fields: Any) -> None:
        """Append one event now; it becomes durable with the next synced journal write.

        For events whose loss in a power cut is harmless (a `started` line: resume redoes any
        trial without data anyway); saves one disk flush per keystroke on a fast sim rig.
        """
        self._journal.write(event, fields, sync=False)

    def journal_many(self, events: list[tuple[str, dict[str, Any]]]) -> None:
        """Append several events with one fsync (e.g. `done` for every trial of a part batch)."""
        self._journal.write_many(events)

    def update_meta(self, **fields: Any) -> None:
        """Merge fields into run.json (atomically)."""
        self._meta.update(fields)
        write_json_atomic(self.paths.run_json, self._meta)

    def add_interruption(self, kind: str, **fields: Any) -> None:
        """Record an interruption (crash, signal, safety stop, ...) in run.json."""
        entry = {"kind": kind, "t_utc": utc_now(), **fields}
        self.update_meta(interruptions=[*self._meta.get("interruptions", []), entry])

    def finish(self, status: str, reason: str | None = None, **fields: Any) -> None:
        """Compact the parts into trials/samples/midi.parquet and set the final status."""
        if status not in RUN_STATUSES or status == "running":
            raise ValueError(f"final status must be one of {RUN_STATUSES[1:]}, got {status!r}")
        self.compact()
        self.update_meta(status=status, reason=reason, end_utc=utc_now(), **fields)

    def compact(self) -> None:
        """Merge committed parts into one file per table; parts are removed only afterwards.

        A compacted file records in its metadata which batches it holds, so a crash between
        writing it and removing the parts never makes a reader count a batch twice.
        """
        self._lock.verify()
        drop_orphan_parts(self.paths)
        parts = self.paths.part_batches()
        committed = sorted(parts["trials"])
        if not committed:
            return
        for name in TABLE_NAMES:
            _compact_table(self.paths, name, committed, parts[name])
        for name in TABLE_NAMES:
            for path in parts[name].values():
                path.unlink(missing_ok=True)

    def close(self) -> None:
        """Release the journal and the run lock (idempotent)."""
        self._journal.close()
        self._lock.release()

    def __enter__(self) -> RunWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def encode_part(table: pd.DataFrame | pa.Table, name: str, run_id: str) -> bytes:
    """One part of table `name` of run `run_id`, encoded as `RunWriter.append` would write it."""
    return encode_parquet(with_metadata(to_table(table, name, run_id), name))


def _compact_table(paths: RunPaths, name: str, committed: list[int], parts: dict[int, Path]) -> None:
    target = paths.table(name)
    held: set[int] = set()
    sources: list[Path] = []
    if target.is_file():
        held = batches_of(pq.read_schema(target).metadata)
        sources.append(target)
    sources += [parts[b] for b in committed if b in parts and b not in held]
    batches = sorted(held | set(committed))
    if name == "trials":
        # Small: one row per keystroke. A trial redone after a failure keeps its last row.
        tables = [pq.read_table(p) for p in sources]
        merged = dedupe_trials(pa.concat_tables(tables, promote_options="default")) if tables else (
            TABLE_SCHEMAS[name].empty_table()
        )
        write_parquet_atomic(target, with_metadata(merged, name, batches))
        return
    # samples and midi can be large: stream them part by part so memory stays bounded.
    schema = with_metadata(TABLE_SCHEMAS[name].empty_table(), name, batches).schema
    temp = target.with_name(f".{target.name}.{os.getpid()}.compact.tmp")
    try:
        with pq.ParquetWriter(temp, schema, **parquet_options(schema)) as out:
            # Text columns (ids, sources) read as dictionaries: no million-fold string copies.
            text = [f.name for f in schema if pa.types.is_string(f.type)]
            for source in sources:
                parquet = pq.ParquetFile(source, read_dictionary=text)
                for group in range(parquet.num_row_groups):
                    out.write_table(parquet.read_row_group(group).cast(schema))
        with open(temp, "rb+") as handle:
            os.fsync(handle.fileno())
        os.replace(temp, target)
    finally:
        temp.unlink(missing_ok=True)
