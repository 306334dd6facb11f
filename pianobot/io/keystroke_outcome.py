"""The trials and MIDI tables of an imported log, and the MIDI outcome of each keystroke.

A keystroke's outcome comes from the press assigned to it: the first note-on (velocity, time,
note), the last note-off after it (release velocity, hold) and the number of note-ons (a double
strike counts two). A press with only a note-off (its note-on never logged) leaves the keystroke
`silent` with the release recorded.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.io.keystroke_assign import Presses
from pianobot.io.keystroke_events import KIND_OFF, KIND_ON
from pianobot.io.keystroke_layouts import PARAMETER_SLOTS
from pianobot.io.keystroke_records import LogRecords

IntArray = npt.NDArray[np.int64]

OUTCOME_COLUMNS = ("on_velocity", "off_velocity", "t_on_s", "t_off_s", "midi_hold_s", "n_note_on")
ASSIGNMENT_COLUMNS = ("read_line", "moved_from_line", "assignment", "assignment_evidence")
MIDI_COLUMNS = ("index", "source_line", "session", "t_s", "type", "note", "velocity", "status")


class OutcomeTable:
    """The output columns of a log, filled session by session."""

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
        self.note = (
            np.full(n, -1, dtype=np.int64) if records.notes is None else records.notes.copy()
        )
        self.read_line = np.full(n, -1, dtype=np.int64)
        self.moved_from = np.full(n, -1, dtype=np.int64)
        self.midi_parts: list[pd.DataFrame] = []

    def trials(self) -> pd.DataFrame:
        r = self.records
        frame = pd.DataFrame(
            {
                "index": np.arange(len(r)),
                "source_line": r.line,
                "session": self.session,
                "status": self.status,
                "note": self.note,
                "finger": r.fingers,
            }
        )
        frame["note"] = frame["note"].where(frame["note"] >= 0).astype("Int64")
        for column in PARAMETER_SLOTS:
            frame[column] = r.params[column].to_numpy() if column in r.params else np.nan
        for column in OUTCOME_COLUMNS:
            frame[column] = self.outcome[column]
        frame["n_note_on"] = frame["n_note_on"].astype("int64")
        frame["read_line"] = pd.array(
            np.where(self.read_line >= 0, self.read_line, 0), dtype="Int64"
        )
        frame.loc[self.read_line < 0, "read_line"] = pd.NA
        frame["moved_from_line"] = pd.array(
            np.where(self.moved_from >= 0, self.moved_from, 0), dtype="Int64"
        )
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


class PressEvents:
    """The presses of a session (runs of events in time order) and their MIDI outcomes."""

    def __init__(self, local: dict[str, IntArray], kind: IntArray, press_of: IntArray) -> None:
        self.local = local
        at = np.flatnonzero(press_of >= 0)  # note events, in time order; presses are runs of them
        self.at = at
        starts = (
            np.flatnonzero(np.diff(press_of[at], prepend=-1)) if at.size else np.zeros(0, np.int64)
        )
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
            t_first_on = np.repeat(
                np.where(has_on, local["t_ms"][at[np.minimum(first_on, at.size - 1)]], big),
                self.n_events,
            )
            off_after = (kind[at] == KIND_OFF) & (local["t_ms"][at] >= t_first_on)
            self.last_off = np.maximum.reduceat(np.where(off_after, position, -1), starts)
            self.any_off = np.maximum.reduceat(np.where(kind[at] == KIND_OFF, position, -1), starts)
            self.t_max = np.maximum.reduceat(local["t_ms"][at], starts)
            read = np.minimum.reduceat(local["record"][at], starts)
        else:
            first = self.n_on = self.n_events = self.last_off = self.any_off = self.t_max = read = (
                np.zeros(0, np.int64)
            )
            has_on = np.zeros(0, dtype=bool)
        self.first = first
        self.presses = Presses(
            local["t_ms"][at[first]] / 1000.0,
            has_on,
            read.astype(np.int64),
            local["note"][at[first]].astype(np.int64),
        )

    def fill(self, table: OutcomeTable, placed: IntArray, rows: IntArray) -> None:
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
        table.note[lone_rows] = np.where(
            table.note[lone_rows] >= 0, table.note[lone_rows], local["note"][lone_off]
        )
        out["off_velocity"][lone_rows] = local["velocity"][lone_off]
        out["t_off_s"][lone_rows] = self.t_max[lone] / 1000.0
