"""What the store itself writes into a run's journal, so damage can be found and undone later.

The runner journals trials (`started`, `done`, ...); the store journals its files:

- `run_created` — run.json as first written (a garbled run.json is rebuilt from it);
- `meta` — each later change to run.json (the fields that changed);
- `part` — a part batch, after its files landed: per table the file, rows, bytes and
  SHA-256, plus a base64 copy of the (small) trials part, so a damaged one can be restored;
- `compacted` — each compacted table before it replaces the old one: rows, bytes, SHA-256 and
  the batches it holds;
- `repaired` — what `runs repair` quarantined, restored, rebuilt, and which batches are lost.

`JournalIndex` reads them back for the integrity check, the repair and the writer.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pianobot.store.journal import BOOKKEEPING_EVENTS, scan_journal
from pianobot.store.layout import TABLE_NAMES

PART = "part"
COMPACTED = "compacted"
RUN_CREATED = "run_created"
META = "meta"
REPAIRED = "repaired"
assert {PART, COMPACTED, RUN_CREATED, META} == BOOKKEEPING_EVENTS
# Trials parts up to this size are copied into the journal (50 trials take ~10 kB).
COPY_MAX_BYTES = 1_000_000


@dataclass(frozen=True)
class FileRecord:
    """A file as it was written: where, how many rows, how many bytes, its SHA-256."""

    file: str  # relative to the run folder
    rows: int
    size: int  # bytes
    sha256: str
    batches: tuple[int, ...] = ()  # compacted tables: the part batches they hold

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"file": self.file, "rows": self.rows, "bytes": self.size,
                               "sha256": self.sha256}
        if self.batches:
            out["batches"] = list(self.batches)
        return out

    @classmethod
    def of_bytes(cls, file: str, data: bytes | memoryview, rows: int, batches: tuple[int, ...] = ()) -> FileRecord:
        return cls(file, rows, len(data), hashlib.sha256(data).hexdigest(), batches)

    @classmethod
    def parse(cls, raw: Any) -> FileRecord | None:
        if not isinstance(raw, dict):
            return None
        try:
            batches = tuple(int(b) for b in raw.get("batches") or ())
            return cls(str(raw["file"]), int(raw["rows"]), int(raw["bytes"]), str(raw["sha256"]),
                       batches)
        except (KeyError, TypeError, ValueError):
            return None


def part_record(
    batch: int, files: dict[str, FileRecord], trials_copy: bytes | memoryview | None
) -> dict[str, Any]:
    """The fields of a `part` event."""
    record: dict[str, Any] = {"batch": batch, "files": {n: f.to_dict() for n, f in files.items()}}
    if trials_copy is not None and len(trials_copy) <= COPY_MAX_BYTES:
        record["copy"] = base64.b64encode(trials_copy).decode("ascii")
    return record


@dataclass
class JournalIndex:
    """The store's records in a journal, plus which batches the runner called done."""

    parts: dict[int, dict[str, FileRecord]] = field(default_factory=dict)  # latest per batch
    copies: dict[int, str] = field(default_factory=dict)  # base64 trials parts
    compacted: dict[str, list[FileRecord]] = field(default_factory=dict)  # every version
    done_batches: set[int] = field(default_factory=set)  # batches with done/failed events
    created: dict[str, Any] | None = None
    meta_updates: list[dict[str, Any]] = field(default_factory=list)
    lost_batches: set[int] = field(default_factory=set)  # quarantined by a repair
    garbled_lines: list[int] = field(default_factory=list)
    events: int = 0

    @property
    def max_batch(self) -> int:
        """The highest batch number the journal mentions (never reuse one)."""
        numbers = set(self.parts) | self.done_batches | self.lost_batches
        for versions in self.compacted.values():
            for record in versions:
                numbers |= set(record.batches)
        return max(numbers, default=0)

    def copy_of(self, batch: int) -> bytes | None:
        """The trials part of `batch` as it was written, if the journal holds a copy."""
        raw = self.copies.get(batch)
        if raw is None:
            return None
        try:
            return base64.b64decode(raw, validate=True)
        except (binascii.Error, ValueError):
            return None

    def rebuilt_meta(self) -> dict[str, Any] | None:
        """run.json as the journal knows it: the created record with every later change."""
        if self.created is None:
            return None
        meta = dict(self.created)
        for update in self.meta_updates:
            meta.update(update)
        return meta


def index_journal(path: Path) -> JournalIndex:
    """Read a run's journal into a `JournalIndex` (garbled lines are counted, not fatal)."""
    events, garbled = scan_journal(path)
    index = JournalIndex(garbled_lines=garbled, events=len(events))
    for event in events:
        kind = event.get("event")
        if kind == PART:
            _index_part(index, event)
        elif kind == COMPACTED:
            for name, raw in (event.get("files") or {}).items():
                record = FileRecord.parse(raw) if name in TABLE_NAMES else None
                if record is not None:
                    index.compacted.setdefault(str(name), []).append(record)
        elif kind in ("done", "failed") and isinstance(event.get("part"), int):
            index.done_batches.add(int(event["part"]))
        elif kind == RUN_CREATED and isinstance(event.get("meta"), dict):
            index.created = dict(event["meta"])
            index.meta_updates.clear()
        elif kind == META and isinstance(event.get("fields"), dict):
            index.meta_updates.append(dict(event["fields"]))
        elif kind == REPAIRED:
            index.lost_batches |= {int(b) for b in event.get("lost_batches") or [] if isinstance(b, int)}
    return index


def _index_part(index: JournalIndex, event: dict[str, Any]) -> None:
    batch = event.get("batch")
    files = event.get("files")
    if not isinstance(batch, int) or not isinstance(files, dict):
        return
    # Only the run's tables: a line a flipped byte left readable may name another ('tr3als').
    parsed = {str(n): r for n, raw in files.items() if n in TABLE_NAMES and (r := FileRecord.parse(raw)) is not None}
    index.parts[batch] = parsed
    index.lost_batches.discard(batch)  # a batch number written again after a repair
    if isinstance(event.get("copy"), str):
        index.copies[batch] = event["copy"]
    else:
        index.copies.pop(batch, None)
