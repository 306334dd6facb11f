"""Repair a damaged run: restore what the journal can restore, quarantine the rest, redo it.

    report = repair_run(paths)     # holds the run lock; raises RunLocked if a writer is live

What it does, file by file (`check_run` says which are damaged):

- **run.json** — rebuilt from the journal (`run_created` plus every later change).
- **plan.parquet** — rebuilt from the spec text run.json recorded (the plan is a pure function
  of it); accepted only if it has the recorded checksum, or at least the same trial ids.
- **a trials part** — restored from its copy in the journal (the bytes that were written).
- **a samples or midi part** — its data is gone: the whole batch (its trials part too) goes
  to quarantine, so its trials count as not done and a resume redoes them. In a finished run
  (trials merged into trials.parquet, samples parts kept as written) the batch's trials and MIDI
  are taken out of trials.parquet and midi.parquet instead (the old files to quarantine).
- **trials.parquet** — rebuilt as parts from the journal's copies of every batch it held.
- **samples.parquet (older runs) or midi.parquet** — gone: the compacted tables go to
  quarantine and the trials they held are redone (their samples or MIDI cannot be had otherwise).

Nothing is deleted: damaged files move to `quarantine/<UTC time>/` under their own names. The
journal gets a `repaired` event and run.json a `repairs` entry; a run that lost trials is
marked `interrupted`, so `pianobot sweep --resume RUN` completes it with each trial once.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from pianobot.errors import InputError
from pianobot.store.integrity import Damage, RunHealth, check_run, parquet_errors
from pianobot.store.journal import Journal
from pianobot.store.layout import (
    COMPACTED_TABLES,
    TABLE_NAMES,
    RunPaths,
    encode_parquet,
    fsync_dir,
    read_json,
    utc_now,
    write_bytes_atomic,
    write_json_atomic,
)
from pianobot.store.lock import RunLock
from pianobot.store.records import (
    COMPACTED,
    META,
    REPAIRED,
    FileRecord,
    JournalIndex,
    index_journal,
)
from pianobot.store.schema import batches_of, with_metadata

_READ_ERRORS = parquet_errors()


@dataclass
class RepairReport:
    """What `repair_run` found and did."""

    run_id: str
    before: RunHealth
    after: RunHealth
    quarantine: str | None = None  # the folder damaged files moved to
    quarantined: list[str] = field(default_factory=list)
    restored: list[str] = field(default_factory=list)
    rebuilt: list[str] = field(default_factory=list)
    lost_batches: list[int] = field(default_factory=list)
    trials_lost: int = 0  # completed keystrokes whose data was lost (to be redone)
    unrepairable: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.after.ok

    def to_dict(self) -> dict[str, Any]:
        return {
            "run_id": self.run_id, "ok": self.ok, "before": self.before.to_dict(),
            "after": self.after.to_dict(), "quarantine": self.quarantine,
            "quarantined": self.quarantined, "restored": self.restored, "rebuilt": self.rebuilt,
            "lost_batches": self.lost_batches, "trials_lost": self.trials_lost,
            "unrepairable": self.unrepairable,
        }

    def lines(self) -> list[str]:
        """What happened, for people."""
        if self.before.ok:
            return [f"run {self.run_id} is intact ({self.before.files_checked} files checked); nothing to repair"]
        out = [f"run {self.run_id}: {len(self.before.damage)} damaged file(s)"]
        out += [f"  restored  {name}" for name in self.restored]
        out += [f"  rebuilt   {name}" for name in self.rebuilt]
        out += [f"  moved to {self.quarantine}: {name}" for name in self.quarantined]
        if self.trials_lost:
            out.append(f"  {self.trials_lost} completed trial(s) lost their data and will be redone "
                       f"(batches {', '.join(map(str, self.lost_batches))})")
        out += [f"  cannot repair: {why}" for why in self.unrepairable]
        if self.ok:
            out.append(f"run {self.run_id} is intact again" +
                       ("; resume it to redo the lost trials" if self.trials_lost else ""))
        else:
            out.append(f"still damaged: {self.after.reason}")
        return out


def repair_run(paths: RunPaths) -> RepairReport:
    """Repair run `paths` (see the module docstring). Raises RunLocked if it is being written."""
    with RunLock(paths.lock, purpose="repair"):
        before = check_run(paths, deep=True)
        report = RepairReport(paths.run_id, before, before)
        if before.ok:
            return report
        fix = _Repair(paths, index_journal(paths.journal), report)
        fix.run(before.damage)
        report.after = check_run(paths, deep=True)
        return report


@dataclass
class _Repair:
    paths: RunPaths
    index: JournalIndex
    report: RepairReport
    folder: Path | None = None
    dropped: set[int] = field(default_factory=set)  # lost batches whose parts were quarantined

    def run(self, damage: tuple[Damage, ...]) -> None:
        by_table: dict[str, list[Damage]] = {}
        for d in damage:
            by_table.setdefault(d.table, []).append(d)
        if "run.json" in by_table:
            self._rebuild_meta()
        if "plan" in by_table:
            self._rebuild_plan()
        parts = [d for d in damage if d.batch is not None]
        compacted = [d for d in damage if d.batch is None and d.table in TABLE_NAMES]
        for batch in sorted({d.batch for d in parts if d.batch is not None}):
            self._repair_batch(batch, [d for d in parts if d.batch == batch])
        if compacted:
            self._repair_compacted({d.table for d in compacted})
        self._drop_from_compacted(self.dropped)  # once: quarantine keeps the files as they were
        self._record()

    # --- files -----------------------------------------------------------------------------

    def _quarantine(self, path: Path) -> None:
        """Move `path` into this repair's quarantine folder, keeping its relative name."""
        if not path.exists():
            return
        if self.folder is None:
            stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
            self.folder = self.paths.quarantine / stamp
            n = 1
            while self.folder.exists():
                n += 1
                self.folder = self.paths.quarantine / f"{stamp}-{n}"
            self.report.quarantine = self.paths.relative(self.folder)
        relative = self.paths.relative(path)
        target = self.folder / relative
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(path, target)
        fsync_dir(path.parent)
        self.report.quarantined.append(relative)

    # --- run.json and plan -------------------------------------------------------------------

    def _rebuild_meta(self) -> None:
        meta = self.index.rebuilt_meta()
        if meta is None:
            self.report.unrepairable.append(
                "run.json: the journal holds no copy of it (a run written by an older pianobot)")
            return
        self._quarantine(self.paths.run_json)
        write_json_atomic(self.paths.run_json, meta)
        self.report.rebuilt.append("run.json")

    def _rebuild_plan(self) -> None:
        try:
            meta = read_json(self.paths.run_json)
        except _READ_ERRORS:
            self.report.unrepairable.append("plan.parquet: run.json, which holds the spec, is damaged too")
            return
        problem = _plan_problem(meta)
        if problem is None:
            try:
                table = _plan_from_spec(meta)
            except InputError as exc:
                problem = f"its spec no longer expands ({exc})"
        if problem is not None:
            self.report.unrepairable.append(f"plan.parquet: {problem}")
            return
        data = encode_parquet(table)
        record = FileRecord.parse(meta.get("plan_file"))
        same_bytes = record is not None and record.sha256 == hashlib.sha256(data).hexdigest()
        same_trials = table.num_rows == meta.get("trials_planned") and self._ids_match(table)
        if not (same_bytes or same_trials):
            self.report.unrepairable.append(
                "plan.parquet: the plan rebuilt from the recorded spec differs from the one the "
                "run started with")
            return
        self._quarantine(self.paths.plan)
        write_bytes_atomic(self.paths.plan, data)
        if not same_bytes:
            # The same trials in other bytes (another pyarrow): record what is on disk now.
            self._update_meta({"plan_file": FileRecord.of_bytes("plan.parquet", data, table.num_rows).to_dict()})
        self.report.rebuilt.append("plan.parquet")

    def _ids_match(self, table: pa.Table) -> bool:
        """Whether every trial the run recorded is in `table` (the plan rebuilt)."""
        ids = set(table.column("trial_id").to_pylist())
        recorded: set[str] = set()
        for batch in self.index.parts:
            copy = self.index.copy_of(batch)
            if copy is not None:
                try:
                    recorded |= set(pq.read_table(pa.BufferReader(copy), columns=["trial_id"])
                                    .column("trial_id").to_pylist())
                except _READ_ERRORS:
                    continue
        return recorded <= ids

    # --- parts and compacted tables ---------------------------------------------------------

    def _repair_batch(self, batch: int, damage: list[Damage]) -> None:
        tables = {d.table for d in damage}
        if tables == {"trials"} and self._restore_trials_part(batch):
            return
        self._lose_batches({batch})

    def _restore_trials_part(self, batch: int) -> bool:
        """Put the journal's copy of a trials part back; False if there is no good copy."""
        copy = self.index.copy_of(batch)
        record = self.index.parts.get(batch, {}).get("trials")
        if copy is None or record is None or hashlib.sha256(copy).hexdigest() != record.sha256:
            return False
        path = self.paths.part("trials", batch)
        self._quarantine(path)
        self.paths.parts.mkdir(exist_ok=True)
        write_bytes_atomic(path, copy)
        self.report.restored.append(self.paths.relative(path))
        return True

    def _repair_compacted(self, damaged: set[str]) -> None:
        held = self._compacted_batches()
        if damaged == {"trials"} and held and all(self._has_copy(b) for b in held):
            # Every batch it held is in the journal: back to parts, compacted again at the end.
            for batch in sorted(held - self.dropped):  # a lost batch's trials stay lost
                if not self.paths.part("trials", batch).exists():
                    copy = self.index.copy_of(batch)
                    assert copy is not None
                    self.paths.parts.mkdir(exist_ok=True)
                    write_bytes_atomic(self.paths.part("trials", batch), copy)
            self._quarantine(self.paths.table("trials"))
            self.report.rebuilt.append(f"trials.parquet (as {len(held)} parts from the journal)")
            return
        # A compacted samples or midi table cannot be had again; the batches it held are redone,
        # except those whose parts are still on disk (compaction had not removed them yet).
        for name in TABLE_NAMES:
            self._quarantine(self.paths.table(name))
        self._lose_batches(held - set(self.paths.part_batches()["trials"]), quarantine_parts=False)

    def _has_copy(self, batch: int) -> bool:
        copy = self.index.copy_of(batch)
        record = self.index.parts.get(batch, {}).get("trials")
        return copy is not None and record is not None and hashlib.sha256(copy).hexdigest() == record.sha256

    def _compacted_batches(self) -> set[int]:
        """The batches the compacted tables hold: from any readable one, else the journal."""
        held: set[int] = set()
        for name in TABLE_NAMES:
            path = self.paths.table(name)
            if path.is_file():
                try:
                    held |= batches_of(pq.read_schema(path).metadata)
                except _READ_ERRORS + (TypeError,):
                    continue
        for versions in self.index.compacted.values():
            if versions:
                held |= set(versions[-1].batches)
        return held

    def _lose_batches(self, batches: set[int], *, quarantine_parts: bool = True) -> None:
        parts = self.paths.part_batches()
        for batch in sorted(batches):
            if quarantine_parts:
                for name in TABLE_NAMES:
                    if batch in parts[name]:
                        self._quarantine(parts[name][batch])
            record = self.index.parts.get(batch, {}).get("trials")
            self.report.trials_lost += record.rows if record is not None else 0
        if quarantine_parts:
            self.dropped |= batches
        self.report.lost_batches = sorted(set(self.report.lost_batches) | batches)

    def _drop_from_compacted(self, batches: set[int]) -> None:
        """Take the trials (and MIDI) of lost batches out of trials.parquet and midi.parquet.

        A finished run's samples files outlive their trials parts (merged into trials.parquet):
        when such a file is lost, its trials must stop counting as done, or a resume would never
        redo them (nor may their MIDI stay, or a redo would double it). Which trials a batch
        held: the journal's copy of its trials part. The old files go to quarantine; the new
        ones are journalled before they replace them.
        """
        if not batches:
            return
        rewrites: list[tuple[str, Path, set[int]]] = []
        for name in COMPACTED_TABLES:
            path = self.paths.table(name)
            try:
                held = batches_of(pq.read_schema(path).metadata)
            except _READ_ERRORS + (TypeError,):
                continue  # absent, or damaged and repaired on its own (`_repair_compacted`)
            if held & batches:
                rewrites.append((name, path, held))
        lost = set().union(*(held & batches for _, _, held in rewrites))
        ids: set[str] = set()
        for batch in sorted(lost):
            copy = self.index.copy_of(batch)
            if copy is None:
                self.report.unrepairable.append(
                    f"trials.parquet: the journal holds no copy of batch {batch}'s trials, so they "
                    "cannot be marked as not done")
                return
            ids |= set(pq.read_table(pa.BufferReader(copy), columns=["trial_id"])
                       .column("trial_id").to_pylist())
        journal = Journal(self.paths.journal)
        try:
            for name, path, held in rewrites:
                table = pq.read_table(path)
                keep = pc.invert(pc.is_in(table.column("trial_id").cast(pa.string()),
                                          value_set=pa.array(sorted(ids), type=pa.string())))
                kept_batches = sorted(held - batches)
                data = encode_parquet(with_metadata(table.filter(keep), name, kept_batches))
                rows = pq.read_metadata(pa.BufferReader(data)).num_rows
                record = FileRecord.of_bytes(self.paths.relative(path), data, rows, tuple(kept_batches))
                journal.write(COMPACTED, {"files": {name: record.to_dict()}})
                self._quarantine(path)
                write_bytes_atomic(path, data)
                self.report.rebuilt.append(f"{name}.parquet (without batches {_listed(held & batches)})")
        finally:
            journal.close()

    # --- the record of it -------------------------------------------------------------------

    def _record(self) -> None:
        report = self.report
        entry = {
            "t_utc": utc_now(),
            "quarantine": report.quarantine,
            "quarantined": report.quarantined,
            "restored": report.restored,
            "rebuilt": report.rebuilt,
            "lost_batches": report.lost_batches,
            "trials_lost": report.trials_lost,
            "unrepairable": report.unrepairable,
        }
        journal = Journal(self.paths.journal)
        try:
            journal.write(REPAIRED, entry)
        finally:
            journal.close()
        try:
            meta = read_json(self.paths.run_json)
        except _READ_ERRORS:
            return  # run.json could not be rebuilt; the journal keeps the record
        # The writer's trial counts may no longer hold: readers count the table until it writes again.
        fields: dict[str, Any] = {"repairs": [*meta.get("repairs", []), entry], "trial_counts": None}
        if report.lost_batches and meta.get("status") in ("completed", "failed", "damaged"):
            fields["status"] = "interrupted"
            fields["reason"] = (f"repaired: {report.trials_lost} trial(s) lost with damaged files; "
                                "resume the run to redo them")
        elif meta.get("status") == "damaged":
            fields["status"], fields["reason"] = "interrupted", "repaired; resume to finish the run"
        self._update_meta(fields)

    def _update_meta(self, fields: dict[str, Any]) -> None:
        meta = read_json(self.paths.run_json)
        meta.update(fields)
        write_json_atomic(self.paths.run_json, meta)
        journal = Journal(self.paths.journal)
        try:
            journal.write(META, {"fields": fields})
        finally:
            journal.close()


def _listed(batches: set[int]) -> str:
    return ", ".join(str(b) for b in sorted(batches))


def _plan_problem(meta: dict[str, Any]) -> str | None:
    if meta.get("kind") != "sweep":
        return f"only a sweep's plan can be rebuilt (this is a {meta.get('kind')!r} run)"
    spec = meta.get("spec")
    if not isinstance(spec, dict) or not isinstance(spec.get("text"), str):
        return "run.json does not hold the spec text"
    return None


def _plan_from_spec(meta: dict[str, Any]) -> pa.Table:
    """plan.parquet of a sweep, from the spec text and the rig its run.json recorded."""
    # Imported here: the plan layer is only needed for this rare rebuild.
    from pydantic import ValidationError

    from pianobot.plan import expand, plan_frame
    from pianobot.plan.approach import apply_approach
    from pianobot.spec import RigSpec, parse_spec_text

    spec = parse_spec_text(str(meta["spec"]["text"]), "the recorded spec")
    rig_record = (meta.get("rig") or {}).get("spec")
    try:
        # The rig the run started with (its fast-approach settings shape the commanded moves).
        rig = RigSpec.model_validate_json(json.dumps(rig_record)) if isinstance(rig_record, dict) else RigSpec()
    except ValidationError as exc:
        raise InputError(f"the recorded rig no longer validates ({exc.error_count()} problems)", "rig") from None
    planned = meta.get("trials_planned")
    trials = apply_approach(spec, expand(spec, max_trials=max(int(planned or 0), 1)), rig)
    table = pa.Table.from_pandas(plan_frame(trials), preserve_index=False)
    return with_metadata(table, "plan")
