"""The imported lines of a keystroke log, and the MIDI clock sessions they fall into.

A *session* is one run of the logging script: a header line, or a timestamp that goes back
(the MIDI clock restarted), starts one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.io.log_lines import LogLines, SkippedLine

IntArray = npt.NDArray[np.int64]


@dataclass
class LogRecords:
    """The imported lines of a log: parameters, notes, extras, and the events each printed."""

    line: IntArray  # file line number of each record
    after_header: npt.NDArray[np.bool_]
    params: pd.DataFrame
    fingers: npt.NDArray[np.object_]
    notes: IntArray | None  # the key of each line when the log names it (-1 where not)
    extra: pd.DataFrame  # the log's own columns pianobot does not know
    sequence: pd.DataFrame  # sequence_id / sequence_order when the log has them
    up_travel: str
    skipped: list[SkippedLine]
    events: dict[str, IntArray]  # record (0..n-1), status, note, velocity, t_ms, order
    columns: dict[str, str] = field(default_factory=dict)

    @classmethod
    def build(
        cls,
        parsed: LogLines,
        keep: IntArray,
        params: pd.DataFrame,
        fingers: npt.NDArray[np.object_],
        notes: IntArray | None,
        extra: pd.DataFrame,
        sequence: pd.DataFrame,
        up_travel: str,
        skipped: list[SkippedLine],
        columns: dict[str, str] | None = None,
    ) -> LogRecords:
        """Records `keep` of a parsed log (events of the other records are dropped with them)."""
        line = np.frombuffer(parsed.line, dtype=np.int64)
        after = np.frombuffer(parsed.after_header, dtype=np.int8).astype(bool)
        new_index = np.full(line.size, -1, dtype=np.int64)
        new_index[keep] = np.arange(keep.size)
        record = (
            new_index[np.frombuffer(parsed.ev_record, dtype=np.int64)]
            if len(parsed.ev_record)
            else np.zeros(0, np.int64)
        )
        kept = record >= 0

        def events(name: str) -> IntArray:
            values = getattr(parsed, name)
            return (
                np.frombuffer(values, dtype=np.int64) if len(values) else np.zeros(0, np.int64)
            )[kept]

        return cls(
            line=line[keep],
            after_header=after[keep],
            params=params.reset_index(drop=True),
            fingers=fingers,
            notes=notes,
            extra=extra,
            sequence=sequence,
            up_travel=up_travel,
            skipped=skipped,
            events={
                "record": record[kept],
                "status": events("ev_status"),
                "note": events("ev_note"),
                "velocity": events("ev_velocity"),
                "t_ms": events("ev_t_ms"),
                "order": np.flatnonzero(kept).astype(np.int64),
            },
            columns=columns or {},
        )

    def __len__(self) -> int:
        return int(self.line.size)


def sessions_of(records: LogRecords) -> IntArray:
    """Session number of each record: a header line or a timestamp going back starts one.

    Without a header the restart happened somewhere after the last line that printed an event
    of the old clock; the lines in between (which printed nothing) go to the new session, so that
    their empty reads are never taken as proof that the old session's last keystrokes were silent.
    """
    n = len(records)
    record, t = records.events["record"], records.events["t_ms"]
    first = np.full(n, np.iinfo(np.int64).max)
    last = np.full(n, -1, dtype=np.int64)
    np.minimum.at(first, record, t)
    np.maximum.at(last, record, t)
    out = np.zeros(n, dtype=np.int64)
    session, latest, last_printing = -1, -1, -1
    for i in range(n):
        if session < 0 or records.after_header[i]:
            session += 1
            latest = -1
        elif last[i] >= 0 and first[i] < latest:
            session += 1
            latest = -1
            out[last_printing + 1 : i] = session
        out[i] = session
        latest = max(latest, int(last[i]))
        if last[i] >= 0:
            last_printing = i
    return out
