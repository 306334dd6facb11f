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

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.io.keystroke_assign import UNDECIDED_MARGIN, Lines, Presses, SessionAssignment, assign_session
from pianobot.io.keystroke_events import KIND_NAMES, KIND_OFF, KIND_ON, event_kinds, group_presses
from pianobot.io.keystroke_timing import LineTiming, line_timing
from pianobot.io.log_lines import LogLines, SkippedLine
from pianobot.progress import NO_PROGRESS, Progress

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]

PARAMETER_COLUMNS = (
    "vacuum_kpa", "finger_angle_deg", "acceleration_mps2", "up_acceleration_mps2",
    "down_velocity_mps", "up_velocity_mps", "depth_m", "distance_m", "hold_s",
    "move_velocity_mps", "move_acceleration_mps2",
)  # fmt: skip
OUTCOME_COLUMNS = ("on_velocity", "off_velocity", "t_on_s", "t_off_s", "midi_hold_s", "n_note_on")
ASSIGNMENT_COLUMNS = ("read_line", "moved_from_line", "assignment", "assignment_evidence")
MIDI_COLUMNS = ("index", "source_line", "session", "t_s", "type", "note", "velocity", "status")
UNREAD_ERROR = "MIDI outcome unknown: the log ends with events still unread (read backlog)"


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
        cls, parsed: LogLines, keep: IntArray, params: pd.DataFrame, fingers: npt.NDArray[np.object_],
        notes: IntArray | None, extra: pd.DataFrame, sequence: pd.DataFrame, up_travel: str,
        skipped: list[SkippedLine], columns: dict[str, str] | None = None,
    ) -> LogRecords:  # fmt: skip
        """Records `keep` of a parsed log (events of the other records are dropped with them)."""
        line = np.frombuffer(parsed.line, dtype=np.int64)
        after = np.frombuffer(parsed.after_header, dtype=np.int8).astype(bool)
        new_index = np.full(line.size, -1, dtype=np.int64)
        new_index[keep] = np.arange(keep.size)
        record = new_index[np.frombuffer(parsed.ev_record, dtype=np.int64)] if len(parsed.ev_record) else np.zeros(0, np.int64)
        kept = record >= 0

        def events(name: str) -> IntArray:
            values = getattr(parsed, name)
            return (np.frombuffer(values, dtype=np.int64) if len(values) else np.zeros(0, np.int64))[kept]

        return cls(
            line=line[keep], after_header=after[keep], params=params.reset_index(drop=True), fingers=fingers,
            notes=notes, extra=extra, sequence=sequence, up_travel=up_travel, skipped=skipped,
            events={"record": record[kept], "status": events("ev_status"), "note": events("ev_note"),
                    "velocity": events("ev_velocity"), "t_ms": events("ev_t_ms"),
                    "order": np.flatnonzero(kept).astype(np.int64)},
            columns=columns or {},
        )  # fmt: skip

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


def assign_events(records: LogRecords, progress: Progress = NO_PROGRESS) -> tuple[pd.DataFrame, pd.DataFrame, dict[str, Any]]:
    """Trials (one row per line), MIDI events and an assignment summary (module docstring)."""
    n = len(records)
    ev = records.events
    reads_all = np.bincount(ev["record"], minlength=n)
    read_size = max(1, int(reads_all.max()) if n else 1)
    timing = line_timing({c: records.params[c].to_numpy(dtype=np.float64) for c in records.params},
                         records.notes, records.up_travel)  # fmt: skip
    session = sessions_of(records)
    table = _Table(records, session)
    bounds = np.flatnonzero(np.diff(session, prepend=-1, append=session[-1] + 1 if n else 0))
    summaries = []
    with progress.task("assigning MIDI events to keystrokes", total=n) as task:
        for s in range(bounds.size - 1):
            a, b = int(bounds[s]), int(bounds[s + 1])
            summaries.append(_session(records, a, b, s, read_size, timing, table))
            task.advance(b - a, note=f"session {s + 1}, lines {records.line[a]}–{records.line[b - 1]}")
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


class _Table:
    """The output columns, filled session by session."""

    def __init__(self, records: LogRecords, session: IntArray) -> None:
        n = len(records)
        self.records = records
        self.session = session
        self.status = np.full(n, "silent", dtype=object)
        self.assignment = np.full(n, "silent", dtype=object)
        self.evidence = np.full(n, None, dtype=object)
        self.error = np.full(n, None, dtype=object)
        self.outcome = {c: np.full(n, np.nan) for c in OUTCOME_COLUMNS}
        self.outcome["n_note_on"] = np.zeros(n)
        self.note = np.full(n, -1, dtype=np.int64) if records.notes is None else records.notes.copy()
        self.read_line = np.full(n, -1, dtype=np.int64)
        self.moved_from = np.full(n, -1, dtype=np.int64)
        self.midi_parts: list[pd.DataFrame] = []

    def trials(self) -> pd.DataFrame:
        r = self.records
        frame = pd.DataFrame({"index": np.arange(len(r)), "source_line": r.line, "session": self.session,
                              "status": self.status, "note": self.note, "finger": r.fingers})  # fmt: skip
        frame["note"] = frame["note"].where(frame["note"] >= 0).astype("Int64")
        for column in PARAMETER_COLUMNS:
            frame[column] = r.params[column].to_numpy() if column in r.params else np.nan
        for column in OUTCOME_COLUMNS:
            frame[column] = self.outcome[column]
        frame["n_note_on"] = frame["n_note_on"].astype("int64")
        frame["read_line"] = pd.array(np.where(self.read_line >= 0, self.read_line, 0), dtype="Int64")
        frame.loc[self.read_line < 0, "read_line"] = pd.NA
        frame["moved_from_line"] = pd.array(np.where(self.moved_from >= 0, self.moved_from, 0), dtype="Int64")
        frame.loc[self.moved_from < 0, "moved_from_line"] = pd.NA
        frame["assignment"], frame["assignment_evidence"] = self.assignment, self.evidence
        frame["error"] = self.error
        for part in (r.sequence, r.extra):
            for column in part.columns:
                frame[column] = part[column].to_numpy()
        return frame

    def midi(self) -> pd.DataFrame:
        if not self.midi_parts:
            return pd.DataFrame({c: [] for c in MIDI_COLUMNS})
        return pd.concat(self.midi_parts, ignore_index=True)[list(MIDI_COLUMNS)]


def _session(records: LogRecords, a: int, b: int, s: int, read_size: int, timing: LineTiming,
             table: _Table) -> dict[str, Any]:  # fmt: skip
    """Assign one session's events (lines a..b-1) and fill its rows of the table."""
    ev = records.events
    inside = (ev["record"] >= a) & (ev["record"] < b)
    order = np.lexsort((ev["order"][inside], ev["t_ms"][inside]))
    local = {k: v[inside][order] for k, v in ev.items()}
    local["record"] = local["record"] - a
    kind = event_kinds(local["status"], local["velocity"])
    press_of = group_presses(local["t_ms"], kind, local["note"])
    found = _PressEvents(local, kind, press_of)
    presses = found.presses
    n_lines = b - a
    line_notes = (records.notes[a:b] if records.notes is not None else np.full(n_lines, -1, dtype=np.int64))
    lines = Lines(np.bincount(local["record"], minlength=n_lines), read_size,
                  timing.take(np.arange(a, b)), line_notes)  # fmt: skip
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
    origin = _backlog_origins(presses.read_line, result.line)
    for i in placed[moved_mask]:
        table.evidence[a + result.line[i]] = _move_evidence(int(i), result, presses, lines, file_line,
                                                            found.n_events, read_size, int(origin[i]))  # fmt: skip
    undecided = 0
    assigned = set(result.line[placed].tolist())
    for i in placed[(result.margin[placed] < UNDECIDED_MARGIN) | result.at_cap[placed]]:
        k, alt = int(result.line[i]), int(result.alternative[i])
        text = _doubt_text(presses.t_s[i], file_line, presses.read_line[i], k, alt, result.margin[i],
                           bool(result.at_cap[i]))  # fmt: skip
        targets = [a + k] + ([a + alt] if alt >= 0 and alt not in assigned else [])
        for row in targets:
            if table.assignment[row] != "undecided":
                undecided += 1
            table.status[row], table.error[row] = "failed", text
            table.assignment[row], table.evidence[row] = "undecided", text
    unread = _mark_unread(table, a, b, result, lines, read_size, file_line)
    _midi_rows(table, local, kind, press_of, result, a, s, file_line)
    unassigned = [
        {"line": int(file_line[presses.read_line[i]]), "t_s": float(presses.t_s[i]), "session": s,
         "note": int(presses.note[i]), "reason": _unassigned_text(reason, presses, i, file_line)}
        for i, reason in sorted(result.unassigned_reason.items())
    ]  # fmt: skip
    if records.notes is None:  # a silent line pressed the log's usual key
        sounded = table.note[a:b][table.note[a:b] >= 0]
        if sounded.size:
            usual = int(np.bincount(sounded).argmax())
            table.note[a:b] = np.where(table.note[a:b] >= 0, table.note[a:b], usual)
    return {
        "first_line": int(file_line[0]), "last_line": int(file_line[-1]), "lines": n_lines,
        "presses": len(presses), "overhead_s": round(result.overhead_s, 4),
        "timing_scale": round(result.sigma_scale, 3), "moved": int(moved_mask.sum()), "unread": unread,
        "undecided": undecided, "unassigned": unassigned,
    }  # fmt: skip


class _PressEvents:
    """The presses of a session (runs of events in time order) and their MIDI outcomes."""

    def __init__(self, local: dict[str, IntArray], kind: IntArray, press_of: IntArray) -> None:
        self.local = local
        at = np.flatnonzero(press_of >= 0)  # note events, in time order; presses are runs of them
        self.at = at
        starts = np.flatnonzero(np.diff(press_of[at], prepend=-1)) if at.size else np.zeros(0, np.int64)
        self.starts = starts
        big = np.iinfo(np.int64).max
        position = np.arange(at.size)
        is_on = kind[at] == KIND_ON
        if at.size:
            first_on = np.minimum.reduceat(np.where(is_on, position, big), starts)
            self.n_on = np.add.reduceat(is_on.astype(np.int64), starts)
            self.n_events = np.diff(np.append(starts, at.size))
            has_on = first_on < big
            first = np.where(has_on, first_on, starts)
            t_first_on = np.repeat(np.where(has_on, local["t_ms"][at[np.minimum(first_on, at.size - 1)]], big),
                                   self.n_events)  # fmt: skip
            off_after = (kind[at] == KIND_OFF) & (local["t_ms"][at] >= t_first_on)
            self.last_off = np.maximum.reduceat(np.where(off_after, position, -1), starts)
            self.any_off = np.maximum.reduceat(np.where(kind[at] == KIND_OFF, position, -1), starts)
            self.t_max = np.maximum.reduceat(local["t_ms"][at], starts)
            read = np.minimum.reduceat(local["record"][at], starts)
        else:
            first = self.n_on = self.n_events = self.last_off = self.any_off = self.t_max = read = np.zeros(0, np.int64)
            has_on = np.zeros(0, dtype=bool)
        self.first = first
        self.presses = Presses(local["t_ms"][at[first]] / 1000.0, has_on, read.astype(np.int64),
                               local["note"][at[first]].astype(np.int64))  # fmt: skip

    def fill(self, table: _Table, placed: IntArray, rows: IntArray) -> None:
        """Write the MIDI outcome of presses `placed` into table rows `rows` (module docstring)."""
        local, at, out = self.local, self.at, table.outcome
        on = self.presses.has_on[placed]
        first = at[self.first[placed]]
        ok_rows, ok_first = rows[on], first[on]
        table.status[ok_rows] = "ok"
        table.note[ok_rows] = local["note"][ok_first]
        out["on_velocity"][ok_rows] = local["velocity"][ok_first]
        out["t_on_s"][ok_rows] = local["t_ms"][ok_first] / 1000.0
        out["n_note_on"][ok_rows] = self.n_on[placed][on]
        last_off = self.last_off[placed][on]
        has_off = last_off >= 0
        off_rows, off_events = ok_rows[has_off], at[last_off[has_off]]
        out["off_velocity"][off_rows] = local["velocity"][off_events]
        out["t_off_s"][off_rows] = local["t_ms"][off_events] / 1000.0
        out["midi_hold_s"][off_rows] = out["t_off_s"][off_rows] - out["t_on_s"][off_rows]
        # only a note-off was logged: the key sounded but its note-on is lost
        lone_rows, lone = rows[~on], placed[~on]
        lone_off = at[np.maximum(self.any_off[lone], 0)]
        table.note[lone_rows] = np.where(table.note[lone_rows] >= 0, table.note[lone_rows], local["note"][lone_off])
        out["off_velocity"][lone_rows] = local["velocity"][lone_off]
        out["t_off_s"][lone_rows] = self.t_max[lone] / 1000.0


def _backlog_origins(read_line: IntArray, line: IntArray) -> IntArray:
    """Per press: the press where its backlog last grew (lag = read line - line)."""
    lag = read_line - line
    origin = np.zeros(line.size, dtype=np.int64)
    for i in range(1, line.size):
        grew = line[i - 1] < 0 or line[i] < 0 or lag[i - 1] < lag[i]
        origin[i] = i if grew else origin[i - 1]
    return origin


def _mark_unread(table: _Table, a: int, b: int, result: SessionAssignment, lines: Lines, read_size: int,
                 file_line: IntArray) -> int:  # fmt: skip
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


def _midi_rows(table: _Table, local: dict[str, IntArray], kind: IntArray, press_of: IntArray,
               result: SessionAssignment, a: int, s: int, file_line: IntArray) -> None:  # fmt: skip
    notes = press_of >= 0
    line = np.where(press_of >= 0, result.line[np.clip(press_of, 0, None)] if result.line.size else -1, -1)
    index = np.where(line >= 0, a + line, -1)[notes]
    table.midi_parts.append(pd.DataFrame({
        "index": index, "source_line": file_line[local["record"][notes]], "session": s,
        "t_s": local["t_ms"][notes] / 1000.0, "type": [KIND_NAMES[k] for k in kind[notes]],
        "note": local["note"][notes], "velocity": local["velocity"][notes], "status": local["status"][notes],
    }))  # fmt: skip


def _move_evidence(i: int, result: SessionAssignment, presses: Presses, lines: Lines, file_line: IntArray,
                   n_events: IntArray, read_size: int, j: int) -> str:  # fmt: skip
    """Why press i left its read line, in words: what fits where, and where the backlog began
    (press j, where its backlog last grew)."""
    k, r = int(result.line[i]), int(presses.read_line[i])
    parts = [f"printed on line {file_line[r]}, belongs to line {file_line[k]}"]
    note = int(presses.note[i])
    if note >= 0 and lines.note[k] == note and lines.note[r] >= 0 and lines.note[r] != note:
        parts.append(f"its note {note} is the key of line {file_line[k]}, not of line {file_line[r]} ({lines.note[r]})")
    own = float(result.own_line_cost[i])
    if math.isfinite(own):
        parts.append(f"keeping it on line {file_line[r]} fits the timestamps and keys worse by {own:.1f} (squared SDs)")
    else:
        parts.append(f"line {file_line[r]} cannot hold it (the presses printed after it need the lines up to it)")
    if j > 0 and result.line[j - 1] < 0:
        parts.append(
            f"backlog from line {file_line[presses.read_line[j - 1]]}: it printed a press of a keystroke the "
            "log never wrote, so later lines printed earlier events"
        )
    elif j > 0:
        origin = int(result.line[j - 1])
        parts.append(
            f"backlog from line {file_line[origin]}: that keystroke's {int(n_events[j - 1])} events outlasted "
            f"its read (a read returns at most {read_size}), so later lines printed earlier events"
        )
    return "; ".join(parts)


def _unassigned_text(reason: str, presses: Presses, i: int, file_line: IntArray) -> str:
    if not reason.startswith("note:"):
        return reason
    first = int(reason.split(":")[1])
    return (f"its note {int(presses.note[i])} is the key of no line it could belong to (lines "
            f"{file_line[first]}–{file_line[presses.read_line[i]]}): a keystroke the log never wrote, "
            "e.g. one cut short by a connection drop")  # fmt: skip


def _doubt_text(t_s: float, file_line: IntArray, read: int, k: int, alt: int, margin: float, capped: bool) -> str:
    if capped:
        return (f"MIDI outcome undecided: the press at {t_s:.3f} s (printed on line {file_line[read]}) lies at "
                "the deepest backlog considered; its keystroke may be further back")  # fmt: skip
    other = f"line {file_line[alt]}" if alt >= 0 else "another line"
    return (f"MIDI outcome undecided: the press at {t_s:.3f} s (printed on line {file_line[read]}) fits "
            f"line {file_line[k]} and {other} almost equally (cost difference {margin:.1f})")  # fmt: skip
