"""RunWriter: creates a run folder and writes its plan, parts, journal and compacted tables.

Everything it writes is recorded in the journal as it lands (`store.records`): run.json as
created and each change to it, every part with its rows and SHA-256 (and a copy of the small
trials part), every compacted table before it replaces the old one. `runs check` verifies a
run against these records, `runs repair` restores from them.
"""

from __future__ import annotations

import os
import shutil
from collections import Counter
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

import pianobot
from pianobot.atomic_files import write_temp
from pianobot.errors import InputError
from pianobot.store.integrity import check_run
from pianobot.store.journal import Journal
from pianobot.store.layout import (
    COMPACTED_TABLES,
    RunDamaged,
    RunPaths,
    check_data_dir,
    committed_batches,
    encode_parquet,
    encode_parquet_view,
    fsync_dir,
    git_commit,
    new_run_id,
    parquet_options,
    read_json,
    resolve_run,
    runs_dir,
    sha256_file,
    utc_now,
    write_bytes_atomic,
    write_json_atomic,
)
from pianobot.store.lock import RunLock, RunLocked  # noqa: F401  (re-exported: RunLocked used to live here)
from pianobot.store.records import (
    COMPACTED,
    META,
    PART,
    RUN_CREATED,
    FileRecord,
    index_journal,
    part_record,
)
from pianobot.store.schema import (
    RUN_KINDS,
    RUN_STATUSES,
    SCHEMA_VERSION,
    TABLE_SCHEMAS,
    TRIAL_STATUSES,
    batches_of,
    storage_schema,
    to_table,
    with_metadata,
)
from pianobot.store.tables import dedupe_trials, drop_orphan_parts, read_run_table

if TYPE_CHECKING:  # pandas takes a third of a second to import: only where frames are made
    import pandas as pd

# Fields of run.json that change with every part batch; journalled without a disk flush of
# their own (they ride on the next one).
_FREQUENT_META = frozenset({"lab_time_s"})


class RunWriter:
    """The one writer of a run folder.

    Create with `RunWriter.create(...)` (a new run) or `RunWriter.reopen(...)` (resume). Each
    `append` writes one batch of parts atomically; `journal` appends an fsync'd line; `finish`
    compacts the trials and midi parts into one file each (samples parts stay as written) and
    records the final status in run.json.
    """

    def __init__(self, paths: RunPaths, *, fsync: bool = True) -> None:
        self.paths = paths
        self._lock = RunLock(paths.lock, purpose="writer").acquire()
        try:
            self._journal = Journal(paths.journal, fsync=fsync)
            self._meta = read_json(paths.run_json)
            known = committed_batches(paths)
        except BaseException:
            self._lock.release()
            raise
        self._has_samples_folder = False
        self._failed: set[str] | None = None  # ids of the trials that ended failed, so far
        self._counts: Counter[str] = Counter()  # trials by the status they ended with last
        # A batch number is never used twice, not even one a repair quarantined.
        self._next_batch = max(max(known, default=0), index_journal(paths.journal).max_batch) + 1

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
        check_data_dir(data_dir)
        base = runs_dir(data_dir)
        try:
            base.mkdir(parents=True, exist_ok=True)
            root = _new_folder(base, name)
        except OSError as exc:
            raise InputError(f"cannot create a run folder: {exc.strerror or exc}", f"--data {data_dir}") from None
        try:
            return cls._fill(RunPaths(root), name=name, kind=kind, meta=meta, plan=plan, fsync=fsync)
        except OSError as exc:
            # Nothing of value is in the new folder yet (no trial ran): leave no half-made run.
            shutil.rmtree(root, ignore_errors=True)
            raise InputError(f"cannot write the run folder: {exc.strerror or exc}", f"--data {data_dir}") from None

    @classmethod
    def _fill(
        cls, paths: RunPaths, *, name: str, kind: str, meta: dict[str, Any],
        plan: pd.DataFrame | None, fsync: bool,
    ) -> RunWriter:
        paths.parts.mkdir()
        paths.samples.mkdir()
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
            data = encode_parquet(with_metadata(table, "plan"))
            write_bytes_atomic(paths.plan, data)
            record["plan_file"] = FileRecord.of_bytes("plan.parquet", data, table.num_rows).to_dict()
        write_json_atomic(paths.run_json, record)
        writer = cls(paths, fsync=fsync)
        writer._failed = set()  # a new run has no trials yet
        writer.journal(RUN_CREATED, meta=record)
        return writer

    @classmethod
    def reopen(cls, data_dir: Path, run_id: str, *, fsync: bool = True) -> RunWriter:
        """Open an existing run to append to it (resume); parts of an unfinished batch are removed.

        Raises:
            InputError: unknown run id.
            RunLocked: another live process holds the run.
        """
        paths = resolve_run(data_dir, run_id)
        try:
            writer = cls(paths, fsync=fsync)
        except PermissionError as exc:
            raise InputError(f"cannot write to run {paths.run_id}: {exc.strerror or exc}",
                             f"--data {data_dir}") from None
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
        renamed, so a reader or a kill sees a whole part or none. Once all have landed, the
        journal records each file's rows and SHA-256 and keeps a copy of the trials part.
        """
        tables = {
            "samples": None if samples is None else to_table(samples, "samples", self.run_id),
            "midi": None if midi is None else to_table(midi, "midi", self.run_id),
            "trials": to_table(trials, "trials", self.run_id),
        }
        self._lock.verify()
        self._samples_folder()
        self._count_stored_trials()
        batch = self._next_batch
        files: dict[str, FileRecord] = {}
        trials_bytes: bytes | memoryview = b""
        for name, table in tables.items():  # trials last: it commits the batch
            if table is not None and (table.num_rows or name == "trials"):
                path = self.paths.part(name, batch)
                data = encode_parquet_view(with_metadata(table, name), part=True)
                write_bytes_atomic(path, data)
                files[name] = FileRecord.of_bytes(self.paths.relative(path), data, table.num_rows)
                trials_bytes = data
        self._next_batch += 1
        self._journal.write(PART, part_record(batch, files, trials_bytes))
        self._count_trials(batch, tables["trials"])
        return batch

    def append_encoded(self, parts: dict[str, bytes | StagedPart]) -> int:
        """Write one batch that was encoded elsewhere (`encode_part`): the same order and
        atomicity as `append` (samples, midi, then the trials part that commits the batch).

        A part may come as bytes, or staged (`stage_part`): already written and fsync'd by the
        worker that encoded it, under a temp name in the folder it belongs in; it is renamed
        into place here (the rename is the write; its record is the worker's size and hash).
        The trials part always comes as bytes (the journal keeps a copy of it).
        """
        trials = parts.get("trials")
        if not isinstance(trials, bytes):
            raise ValueError("an encoded batch needs its trials part, as bytes")
        self._lock.verify()  # the run is still ours (a parallel sweep's driver holds the lock)
        self._samples_folder()
        self._count_stored_trials()
        batch = self._next_batch
        files: dict[str, FileRecord] = {}
        for name in ("samples", "midi", "trials"):
            part = parts.get(name)
            if part is None:
                continue
            path = self.paths.part(name, batch)
            relative = self.paths.relative(path)
            if isinstance(part, StagedPart):
                files[name] = part.commit(path, relative)
            else:
                write_bytes_atomic(path, part)
                rows = pq.read_metadata(pa.BufferReader(part)).num_rows
                files[name] = FileRecord.of_bytes(relative, part, rows)
        self._next_batch += 1
        self._journal.write(PART, part_record(batch, files, trials))
        columns = ["trial_id", "status"]
        self._count_trials(batch, pq.read_table(pa.BufferReader(trials), columns=columns))
        return batch

    def _count_trials(self, batch: int, trials: pa.Table) -> None:
        """Keep run.json's `trial_counts` (ok, silent, failed; the last batch they include)
        current, so `pianobot runs` lists a run without reading its tables.

        A trial is written again only after it failed (a resume takes the ok and silent ones
        from the data), so only the failed trials' ids are kept: memory stays flat over a
        million-trial run. The counts are written with the next change to run.json (the runner
        records the lab time after every batch); a reader that finds them behind the run's last
        batch counts the trials table instead.
        """
        assert self._failed is not None, "the stored counts are read before a part lands"
        if "status" in trials.column_names:
            for trial_id, status in zip(trials.column("trial_id").to_pylist(),
                                        trials.column("status").to_pylist(), strict=True):
                if trial_id in self._failed:  # redone: it counts as it ended last
                    self._counts["failed"] -= 1
                    self._failed.discard(trial_id)
                self._counts[status] += 1
                if status == "failed":
                    self._failed.add(trial_id)
        counts = {status: self._counts[status] for status in TRIAL_STATUSES}
        self._meta["trial_counts"] = {**counts, "batch": batch}

    def _count_stored_trials(self) -> None:
        """The counts of a reopened run, from its trials table, before its next part lands."""
        if self._failed is not None:
            return
        stored = read_run_table(self.paths, "trials", columns=["trial_id", "status"])
        status = stored.column("status")
        self._counts = Counter({str(entry["values"]): int(entry["counts"])
                                for entry in pc.value_counts(status).to_pylist()})
        self._failed = set(stored.column("trial_id").filter(pc.equal(status, "failed")).to_pylist())

    def _samples_folder(self) -> None:
        """samples/ exists (a run an older pianobot started has none until it is resumed)."""
        if not self._has_samples_folder:
            if not self.paths.samples.is_dir():
                self.paths.samples.mkdir()
                fsync_dir(self.paths.root)  # the folder's entry is as durable as the files in it
            self._has_samples_folder = True

    def replace_plan(self, plan: pd.DataFrame) -> None:
        """Write a new plan.parquet (atomically) and record it: its rows and SHA-256 in run.json
        (`plan_file`, journalled), `trials_planned` = its rows. For a run whose plan is only known
        once it started (`play`: the warm-up as played, then the song)."""
        self._lock.verify()
        table = pa.Table.from_pandas(plan, preserve_index=False)
        data = encode_parquet(with_metadata(table, "plan"))
        write_bytes_atomic(self.paths.plan, data)
        record = FileRecord.of_bytes("plan.parquet", data, table.num_rows)
        self.update_meta(trials_planned=table.num_rows, plan_file=record.to_dict())

    def journal(self, event: str, **fields: Any) -> None:
        """Append one event to journal.jsonl (fsync'd)."""
        self._journal.write(event, fields)

    def journal_deferred(self, event: str, **fields: Any) -> None:
        """Append one event now; it becomes durable with the next synced journal write.

        For events whose loss in a power cut is harmless (a `started` line: resume redoes any
        trial without data anyway); saves one disk flush per keystroke on a fast sim rig.
        """
        self._journal.write(event, fields, sync=False)

    def journal_many(self, events: list[tuple[str, dict[str, Any]]], *, sync: bool = True) -> None:
        """Append several events with one fsync (e.g. `done` for every trial of a part batch);
        `sync=False`: durable with the next synced write (as `journal_deferred`)."""
        self._journal.write_many(events, sync=sync)

    def update_meta(self, **fields: Any) -> None:
        """Merge fields into run.json (atomically); the change is journalled too."""
        self._meta.update(fields)
        write_json_atomic(self.paths.run_json, self._meta)
        self._journal.write(META, {"fields": fields}, sync=not set(fields) <= _FREQUENT_META)

    def add_interruption(self, kind: str, **fields: Any) -> None:
        """Record an interruption (crash, signal, safety stop, ...) in run.json."""
        entry = {"kind": kind, "t_utc": utc_now(), **fields}
        self.update_meta(interruptions=[*self._meta.get("interruptions", []), entry])

    def finish(self, status: str, reason: str | None = None, **fields: Any) -> None:
        """Verify and compact the parts into trials/samples/midi.parquet, set the final status.

        A run whose files fail the check is not compacted and not declared complete: its status
        becomes `damaged` with the first problem as the reason (`pianobot runs repair`).
        """
        if status not in RUN_STATUSES or status == "running":
            raise ValueError(f"final status must be one of {RUN_STATUSES[1:]}, got {status!r}")
        try:
            self.compact()
        except RunDamaged as exc:
            status, reason = "damaged", f"{exc.problem} (was {status}: {reason or 'no reason'})"
        self.update_meta(status=status, reason=reason, end_utc=utc_now(), **fields)

    def compact(self) -> None:
        """Merge committed trials and midi parts into one file each; parts are removed only
        afterwards. Samples parts are the stored samples: written once, never re-encoded.

        Every part is verified first (readable, rows and SHA-256 as journalled); each compacted
        file is checked (rows) and journalled before it replaces the old one. It records in its
        metadata which batches it holds, so a crash between writing it and removing the parts
        never makes a reader count a batch twice.

        Raises:
            RunDamaged: a part or a compacted file is damaged; nothing was changed.
        """
        self._lock.verify()
        drop_orphan_parts(self.paths)
        # The parts about to be merged are hashed against their records (no damage is folded
        # into a new file); samples parts stay as written, so their rows are checked only.
        health = check_run(self.paths, deep=True, hash_tables=COMPACTED_TABLES)
        if not health.ok:
            raise RunDamaged(health.reason, self.run_id)
        parts = self.paths.part_batches()
        committed = sorted(parts["trials"])
        if not committed:
            return
        for name in COMPACTED_TABLES:
            _compact_table(self.paths, name, committed, parts[name], self._journal)
        for name in COMPACTED_TABLES:
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
    return encode_parquet(with_metadata(to_table(table, name, run_id), name), part=True)


@dataclass(frozen=True)
class StagedPart:
    """A part written ahead by a worker (`stage_part`), waiting for the writer to commit it."""

    temp: str  # the temp file: in the part's own folder, named as the store sweeps leftovers
    record: FileRecord  # rows, size and SHA-256 as the worker wrote it (its file: the temp name)

    def commit(self, path: Path, relative: str) -> FileRecord:
        """Rename the staged file to `path` (same folder: atomic) and make the rename durable.

        Raises:
            RunDamaged: the staged file is gone or is not the size the worker wrote.
        """
        temp = Path(self.temp)
        if temp.parent.resolve() != path.parent.resolve():
            raise ValueError(f"a part staged in {temp.parent} cannot become {path}")
        try:
            size = temp.stat().st_size
        except FileNotFoundError:
            size = -1
        if size != self.record.size:
            raise RunDamaged(f"the staged part {temp.name} is {'gone' if size < 0 else f'{size} bytes'}, "
                             f"not the {self.record.size} bytes its worker wrote", path.parent.parent.name)
        os.replace(temp, path)
        fsync_dir(path.parent)
        return replace(self.record, file=relative)


def stage_part(folder: Path | str, data: bytes, rows: int) -> StagedPart:
    """Write an encoded part ahead of its commit, as a worker sharing the run's file system does:
    under a temp name in `folder` (the part's folder: the run's samples folder for a samples
    part), fsync'd, with its size and SHA-256. Readers never see it; the run's writer commits it
    (`RunWriter.append_encoded`) or sweeps it as a leftover (`drop_orphan_parts`)."""
    target = Path(folder)
    target.mkdir(parents=True, exist_ok=True)
    temp = write_temp(target / "staged.parquet", data)
    return StagedPart(str(temp), FileRecord.of_bytes(temp.name, data, rows))


def _new_folder(base: Path, name: str) -> Path:
    for _ in range(20):
        root = base / new_run_id(name)
        try:
            root.mkdir()
            return root
        except FileExistsError:
            continue
    raise FileExistsError(f"could not find a free run id in {base}")


def _compact_table(
    paths: RunPaths, name: str, committed: list[int], parts: dict[int, Path], journal: Journal
) -> None:
    target = paths.table(name)
    held: set[int] = set()
    sources: list[Path] = []
    if target.is_file():
        held = batches_of(pq.read_schema(target).metadata)
        sources.append(target)
    sources += [parts[b] for b in committed if b in parts and b not in held]
    batches = sorted(held | set(committed))
    temp = target.with_name(f".{target.name}.{os.getpid()}.compact.tmp")
    try:
        if name == "trials":
            # Small: one row per keystroke. A trial redone after a failure keeps its last row.
            tables = [pq.read_table(p) for p in sources]
            merged = dedupe_trials(pa.concat_tables(tables, promote_options="default")) if tables else (
                TABLE_SCHEMAS[name].empty_table()
            )
            expected = merged.num_rows
            write_bytes_atomic(temp, encode_parquet(with_metadata(merged, name, batches)))
        else:
            # samples and midi can be large: stream them part by part so memory stays bounded.
            schema = with_metadata(storage_schema(name).empty_table(), name, batches).schema
            expected = 0
            with pq.ParquetWriter(temp, schema, **parquet_options(schema)) as out:
                # Dictionary text columns (ids, sources) stay dictionaries from part to file:
                # no string is copied or hashed per row (parts of an older pianobot are cast).
                text = [f.name for f in schema if pa.types.is_dictionary(f.type)]
                for source in sources:
                    parquet = pq.ParquetFile(source, read_dictionary=text)
                    for group in range(parquet.num_row_groups):
                        rows = parquet.read_row_group(group)
                        if not rows.schema.equals(schema, check_metadata=False):
                            rows = rows.cast(schema)
                        expected += rows.num_rows
                        out.write_table(rows)
            with open(temp, "rb+") as handle:
                os.fsync(handle.fileno())
        # Read back what landed before it replaces anything: a short write never wins.
        rows = pq.read_metadata(temp).num_rows
        if rows != expected:
            raise RunDamaged(f"compacting {name} wrote {rows} rows, expected {expected}", paths.run_id)
        record = FileRecord(paths.relative(target), rows, temp.stat().st_size, sha256_file(temp),
                            tuple(batches))
        journal.write(COMPACTED, {"files": {name: record.to_dict()}})
        os.replace(temp, target)
    finally:
        temp.unlink(missing_ok=True)
