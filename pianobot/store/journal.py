"""The run journal: one JSON object per line, appended and fsync'd, never rewritten.

Each line is `{"t_utc": ..., "event": ..., **fields}`. The runner journals `started` before a
trial and `done` only after the trial's part is on disk, so after a crash the journal never
claims more than the data holds. A line cut short by a kill is ignored by the reader.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from pianobot.store.layout import utc_now


class Journal:
    """An append-only JSON-lines file.

    Each event is one `os.write` on an O_APPEND descriptor, so concurrent readers see whole
    lines; `fsync=True` also survives a power cut, at the cost of one disk flush per event.
    """

    def __init__(self, path: Path, *, fsync: bool = True) -> None:
        self.path = path
        self.fsync = fsync
        self._fd: int | None = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        self._repair_tail()

    def _repair_tail(self) -> None:
        # A kill in the middle of a write could leave a line without its newline; start the
        # next event on a fresh line so that only the torn line is lost.
        size = self.path.stat().st_size
        if size == 0:
            return
        with open(self.path, "rb") as handle:
            handle.seek(size - 1)
            last = handle.read(1)
        if last != b"\n":
            self._write(b"\n")

    def write(self, event: str, fields: dict[str, Any], *, sync: bool = True) -> None:
        """Append one event (JSON-serialisable fields; NaN is written as null).

        With `sync=False` the line is visible to readers and survives a killed process at once,
        but reaches the disk with the next synced write: fsync flushes the whole file, so a
        durable line implies every line before it is durable too.
        """
        self.write_many([(event, fields)], sync=sync)

    def write_many(self, events: list[tuple[str, dict[str, Any]]], *, sync: bool = True) -> None:
        """Append several events with one write and (optionally) one fsync."""
        if not events:
            return
        now = utc_now()
        lines = [
            json.dumps(_nan_to_none({"t_utc": now, "event": event, **fields}), default=str, separators=(",", ":"))
            + "\n"
            for event, fields in events
        ]
        self._write("".join(lines).encode(), sync=sync)

    def sync(self) -> None:
        """Make every line written so far durable."""
        if self._fd is not None and self.fsync:
            os.fsync(self._fd)

    def _write(self, data: bytes, *, sync: bool = True) -> None:
        if self._fd is None:
            raise ValueError(f"journal {self.path} is closed")
        os.write(self._fd, data)
        if sync and self.fsync:
            os.fsync(self._fd)

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


# The store's own records of the files it wrote (`store.records`): bookkeeping for the
# integrity check, left out of what `read_journal` shows.
BOOKKEEPING_EVENTS = frozenset({"run_created", "meta", "part", "compacted"})


def read_journal(path: Path, *, bookkeeping: bool = False) -> list[dict[str, Any]]:
    """Every complete event of a journal, in order (a torn or garbled line is skipped).

    The store's bookkeeping records are left out unless `bookkeeping` is set.
    """
    events = scan_journal(path)[0]
    if bookkeeping:
        return events
    return [e for e in events if e.get("event") not in BOOKKEEPING_EVENTS]


def scan_journal(path: Path) -> tuple[list[dict[str, Any]], list[int]]:
    """(every complete event, the 1-based numbers of garbled lines) of a journal.

    The last line without its newline is a write cut short by a kill: normal, not garbled.
    """
    events: list[dict[str, Any]] = []
    garbled: list[int] = []
    if not path.is_file():
        return events, garbled
    with open(path, "rb") as handle:
        for number, raw in enumerate(handle, start=1):
            if not raw.endswith(b"\n"):
                break  # the writer is mid-line or was killed mid-line
            try:
                record = json.loads(raw)
            except ValueError:  # JSONDecodeError, or bytes that are not UTF-8
                garbled.append(number)
                continue
            if isinstance(record, dict) and "event" in record:
                events.append(record)
            elif raw.strip():
                garbled.append(number)
    return events, garbled


def _nan_to_none(value: Any) -> Any:
    if isinstance(value, float):
        return None if value != value else value
    if isinstance(value, dict):
        # Most fields are plain values: recurse only into containers (a line per keystroke).
        return {k: (v if v.__class__ in _PLAIN else _nan_to_none(v)) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_nan_to_none(v) for v in value]
    return value


_PLAIN = frozenset({str, int, bool, type(None)})
