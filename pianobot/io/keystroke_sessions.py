"""From a log's records to its trials and MIDI tables: clock sessions, presses, assignment.

A *session* is one run of the logging script: a header line, or a timestamp that goes back
(the MIDI clock restarted), starts one. Within a session the events are grouped into presses
(`keystroke_events`), and each press is given to a keystroke line (`keystroke_assign`). Every
line then gets its outcome: `ok` (a press with a note-on), `silent` (proven: a later read emptied
the buffer or read a later keystroke's events), or `failed` with the reason when the log cannot
tell: the session ended while every read was full, so the line's events may never have been read
(*unread*), or two lines fit its press almost equally (*undecided*).

Each trial records where its events were printed (`read_line`), `moved_from_line` when that is
not its own line, `assignment` (own line | moved | silent | unread | undecided) and the
evidence for a move or a doubt in words (`assignment_evidence`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.io.keystroke_assign import UNDECIDED_MARGIN, Lines, SessionAssignment, assign_session
from pianobot.io.keystroke_events import KIND_NAMES, event_kinds, group_presses
from pianobot.io.keystroke_evidence import (
    backlog_origins,
    doubt_text,
    move_evidence,
    unassigned_text,
)
from pianobot.io.keystroke_outcome import MIDI_COLUMNS, OutcomeTable, PressEvents
from pianobot.io.keystroke_records import LogRecords, sessions_of
from pianobot.io.keystroke_timing import LineTiming, line_timing
from pianobot.progress import NO_PROGRESS, Progress

IntArray = npt.NDArray[np.int64]
UNREAD_ERROR = "MIDI outcome unknown: the log ends with events still unread (read backlog)"

__all__ = ["MIDI_COLUMNS", "LogRecords", "assign_events", "sessions_of"]


def assign_events(
    records: LogRecords, progress: Progress = NO_PROGRESS
) -> tuple[pd.DataFrame, pd.DataFrame, dict[str, Any]]:
    """Trials (one row per line), MIDI events and an assignment summary (module docstring)."""
    n = len(records)
    ev = records.events
    reads_all = np.bincount(ev["record"], minlength=n)
    read_size = max(1, int(reads_all.max()) if n else 1)
    timing = line_timing(
        {str(c): records.params[c].to_numpy(dtype=np.float64) for c in records.params},
        records.notes,
        records.up_travel,
    )
    session = sessions_of(records)
    table = OutcomeTable(records, session)
    bounds = np.flatnonzero(np.diff(session, prepend=-1, append=session[-1] + 1 if n else 0))
    summaries = []
    with progress.task("assigning MIDI events to keystrokes", total=n) as task:
        for s in range(bounds.size - 1):
            a, b = int(bounds[s]), int(bounds[s + 1])
            summaries.append(_session(records, a, b, s, read_size, timing, table))
            task.advance(
                b - a, note=f"session {s + 1}, lines {records.line[a]}–{records.line[b - 1]}"
            )
    summary = {
        "method": "pianobot.io.keystroke_assign: FIFO read structure + predicted stroke timing",
        "read_size": read_size,
        "sessions": len(summaries),
        "moved": sum(x["moved"] for x in summaries),
        "unread": sum(x["unread"] for x in summaries),
        "undecided": sum(x["undecided"] for x in summaries),
        "unassigned_presses": [p for x in summaries for p in x.pop("unassigned")],
        "per_session": summaries,
    }
    return table.trials(), table.midi(), summary


def _session(
    records: LogRecords,
    a: int,
    b: int,
    s: int,
    read_size: int,
    timing: LineTiming,
    table: OutcomeTable,
) -> dict[str, Any]:
    """Assign one session's events (lines a..b-1) and fill its rows of the table."""
    ev = records.events
    inside = (ev["record"] >= a) & (ev["record"] < b)
    order = np.lexsort((ev["order"][inside], ev["t_ms"][inside]))
    local = {k: v[inside][order] for k, v in ev.items()}
    local["record"] = local["record"] - a
    kind = event_kinds(local["status"], local["velocity"])
    press_of = group_presses(local["t_ms"], kind, local["note"])
    found = PressEvents(local, kind, press_of)
    presses = found.presses
    n_lines = b - a
    line_notes = (
        records.notes[a:b] if records.notes is not None else np.full(n_lines, -1, dtype=np.int64)
    )
    lines = Lines(
        np.bincount(local["record"], minlength=n_lines),
        read_size,
        timing.take(np.arange(a, b)),
        line_notes,
    )
    result = assign_session(presses, lines)
    file_line = records.line[a:b]
    placed = np.flatnonzero(result.line >= 0)
    rows = a + result.line[placed]
    found.fill(table, placed, rows)
    read = presses.read_line[placed]
    table.read_line[rows] = file_line[read]
    moved_mask = result.line[placed] != read
    table.assignment[rows] = np.where(moved_mask, "moved", "own line")
    table.moved_from[rows[moved_mask]] = file_line[read[moved_mask]]
    origin = backlog_origins(presses.read_line, result.line)
    for i in placed[moved_mask]:
        table.evidence[a + result.line[i]] = move_evidence(
            int(i), result, presses, lines, file_line, found.n_events, read_size, int(origin[i])
        )
    undecided = 0
    assigned = set(result.line[placed].tolist())
    for i in placed[(result.margin[placed] < UNDECIDED_MARGIN) | result.at_cap[placed]]:
        k, alt = int(result.line[i]), int(result.alternative[i])
        text = doubt_text(
            presses.t_s[i],
            file_line,
            presses.read_line[i],
            k,
            alt,
            result.margin[i],
            bool(result.at_cap[i]),
        )
        targets = [a + k] + ([a + alt] if alt >= 0 and alt not in assigned else [])
        for row in targets:
            if table.assignment[row] != "undecided":
                undecided += 1
            table.status[row], table.error[row] = "failed", text
            table.assignment[row], table.evidence[row] = "undecided", text
    unread = _mark_unread(table, a, b, result, lines, read_size, file_line)
    _midi_rows(table, local, kind, press_of, result, a, s, file_line)
    unassigned = [
        {
            "line": int(file_line[presses.read_line[i]]),
            "t_s": float(presses.t_s[i]),
            "session": s,
            "note": int(presses.note[i]),
            "reason": unassigned_text(reason, presses, i, file_line),
        }
        for i, reason in sorted(result.unassigned_reason.items())
    ]
    if records.notes is None:  # a silent line pressed the log's usual key
        sounded = table.note[a:b][table.note[a:b] >= 0]
        if sounded.size:
            usual = int(np.bincount(sounded).argmax())
            table.note[a:b] = np.where(table.note[a:b] >= 0, table.note[a:b], usual)
    return {
        "first_line": int(file_line[0]),
        "last_line": int(file_line[-1]),
        "lines": n_lines,
        "presses": len(presses),
        "overhead_s": round(result.overhead_s, 4),
        "timing_scale": round(result.sigma_scale, 3),
        "moved": int(moved_mask.sum()),
        "unread": unread,
        "undecided": undecided,
        "unassigned": unassigned,
    }


def _mark_unread(
    table: OutcomeTable,
    a: int,
    b: int,
    result: SessionAssignment,
    lines: Lines,
    read_size: int,
    file_line: IntArray,
) -> int:
    """Lines after the session's last read keystroke whose reads were all full: outcome unknown."""
    assigned = result.line[result.line >= 0]
    last_press = int(assigned.max()) if assigned.size else -1
    drains = np.flatnonzero(lines.reads < read_size)
    last_drain = int(drains.max()) if drains.size else -1
    first_unread = max(last_press, last_drain) + 1
    count = 0
    for k in range(first_unread, b - a):
        if table.status[a + k] != "silent":
            continue
        table.status[a + k], table.assignment[a + k] = "failed", "unread"
        table.error[a + k] = UNREAD_ERROR
        table.evidence[a + k] = (
            f"every read from line {file_line[first_unread]} to the end of the session (line {file_line[-1]}) "
            f"returned {read_size} events, so this keystroke's events may still have been in the buffer"
        )
        count += 1
    return count


def _midi_rows(
    table: OutcomeTable,
    local: dict[str, IntArray],
    kind: IntArray,
    press_of: IntArray,
    result: SessionAssignment,
    a: int,
    s: int,
    file_line: IntArray,
) -> None:
    notes = press_of >= 0
    line = np.where(
        press_of >= 0, result.line[np.clip(press_of, 0, None)] if result.line.size else -1, -1
    )
    index = np.where(line >= 0, a + line, -1)[notes]
    table.midi_parts.append(
        pd.DataFrame(
            {
                "index": index,
                "source_line": file_line[local["record"][notes]],
                "session": s,
                "t_s": local["t_ms"][notes] / 1000.0,
                "type": [KIND_NAMES[k] for k in kind[notes]],
                "note": local["note"][notes],
                "velocity": local["velocity"][notes],
                "status": local["status"][notes],
            }
        )
    )
