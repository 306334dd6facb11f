"""Reader of the study's old keystroke logs: one Python-literal dict per line.

    {'control': [60, 45, 0.5, 0.03, 0.04, 0.05, 0], 'midi': [[[144, 57, 1, 0], 468620], ...]}

Lines are parsed with `ast.literal_eval` (never `eval`; bare `nan`/`inf` are accepted). Dicts
without `control`/`midi` (e.g. `start_position_l`) are headers: metadata that also starts a new
session. Malformed lines are reported (line number, reason) and the rest is imported. Control
lists are decoded by a layout (see `keystroke_layouts`); MIDI events are re-assigned to keystrokes
by timestamp (see `keystroke_events`). `read_keystroke_log(path)` returns a `KeystrokeLog`.
"""

from __future__ import annotations

import ast
import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pianobot.errors import InputError
from pianobot.io.keystroke_events import LogEvent, Press, assign_presses, group_presses
from pianobot.io.keystroke_layouts import LAYOUT_CHOICES, Layout, choose_layout
from pianobot.io.source import read_input_bytes
from pianobot.physics.trajectory import move_profile

# A session of the study logged a few hundred keystrokes; a million lines is a week of
# non-stop pressing. Checked before anything is parsed.
MAX_LOG_LINES = 1_000_000

TRIAL_COLUMNS = (
    "index", "source_line", "session", "status", "note", "finger",
    "vacuum_kpa", "finger_angle_deg", "acceleration_mps2", "up_acceleration_mps2",
    "down_velocity_mps", "up_velocity_mps", "depth_m", "distance_m", "hold_s",
    "on_velocity", "off_velocity", "t_on_s", "t_off_s", "midi_hold_s", "n_note_on", "error",
)  # fmt: skip
UNREAD_ERROR = "MIDI outcome unknown: the log ends with events still unread (read backlog)"
MIDI_COLUMNS = ("index", "source_line", "session", "t_s", "type", "note", "velocity", "status")


@dataclass(frozen=True)
class SkippedLine:
    """A line that was not imported, and why."""

    line: int
    reason: str

    def to_dict(self) -> dict[str, Any]:
        return {"line": self.line, "reason": self.reason}


@dataclass(frozen=True)
class KeystrokeLog:
    """A parsed log.

    `trials`: one row per keystroke line (pianobot column names; `t_on_s`/`t_off_s` are seconds
    on the session's MIDI clock, i.e. since the MIDI init of that script run). `midi`: every note
    event with the keystroke `index` it was assigned to (by timestamp) and the `source_line` that
    printed it. `header`: the first header dict; `headers`: all of them with their line numbers.
    """

    path: Path
    layout: str
    finger: str
    trials: pd.DataFrame
    midi: pd.DataFrame
    skipped: tuple[SkippedLine, ...]
    header: dict[str, Any]
    headers: tuple[tuple[int, dict[str, Any]], ...] = field(default=())
    n_sessions: int = 1


@dataclass(frozen=True)
class _Record:
    line: int
    control: tuple[float, ...]
    events: tuple[tuple[int, int, int, int], ...]  # (status, note, velocity, t_ms)
    header_acc: float | None
    after_header: bool


def read_keystroke_log(path: Path | str, layout: str = "auto") -> KeystrokeLog:
    """Parse a dict-per-line keystroke log.

    Args:
        path: the log file.
        layout: "auto", "soft-2022", "rigid-2022", or a concrete layout name (see
            `keystroke_layouts.LAYOUT_CHOICES`).

    Raises:
        InputError: unknown layout; the file is missing, empty, binary or holds no keystroke line.
    """
    path = Path(path)
    where = str(path)
    if layout not in LAYOUT_CHOICES:
        raise InputError(
            f"layout should be one of {sorted(LAYOUT_CHOICES)}, got {layout!r}", "--layout"
        )
    lines = _read_lines(path)
    records, headers, skipped = _parse_lines(lines)
    if not records:
        reasons = "; ".join(f"line {s.line}: {s.reason}" for s in skipped[:3])
        raise InputError(
            f"no keystroke line ({{'control': [...], 'midi': [...]}}) found{': ' + reasons if reasons else ''}",
            where,
        )
    chosen = choose_layout(layout, [r.control for r in records])
    lengths = sorted({len(r.control) for r in records})
    if chosen is None:
        raise InputError(f"no known layout has {lengths} control values (layout {layout!r})", where)
    kept = []
    for record in records:
        if len(record.control) != len(chosen.slots):
            skipped.append(
                SkippedLine(
                    record.line,
                    f"control has {len(record.control)} values, layout {chosen.name} expects {len(chosen.slots)}",
                )
            )
        else:
            kept.append(record)
    if not kept:
        raise InputError(f"no line fits layout {chosen.name}", where)
    trials, midi, n_sessions = _build_tables(kept, chosen)
    skipped.sort(key=lambda s: s.line)
    fingers = Counter(chosen.finger_of(r.control) for r in kept)
    return KeystrokeLog(
        path=path,
        layout=chosen.name,
        finger=fingers.most_common(1)[0][0],
        trials=trials,
        midi=midi,
        skipped=tuple(skipped),
        header=headers[0][1] if headers else {},
        headers=tuple(headers),
        n_sessions=n_sessions,
    )


def _read_lines(path: Path) -> list[str]:
    where = str(path)
    data = read_input_bytes(path, "a text log")
    lines = data.count(b"\n") + (not data.endswith(b"\n"))
    if lines > MAX_LOG_LINES:
        raise InputError(f"has {lines:,} lines; a keystroke log is read up to {MAX_LOG_LINES:,} "
                         "lines (split it into sessions)", where)
    try:
        # utf-8-sig: a byte-order mark (Windows editors add one) is not part of the first record.
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError("not a text log (not UTF-8 text)", where) from None
    return text.splitlines()


def _parse_lines(
    lines: list[str],
) -> tuple[list[_Record], list[tuple[int, dict[str, Any]]], list[SkippedLine]]:
    records: list[_Record] = []
    headers: list[tuple[int, dict[str, Any]]] = []
    skipped: list[SkippedLine] = []
    header_acc: float | None = None
    after_header = False
    for number, raw in enumerate(lines, start=1):
        text = raw.strip()
        if not text:
            continue
        try:
            value = _literal(text)
        except ValueError as exc:
            skipped.append(SkippedLine(number, f"not a Python literal ({exc})"))
            continue
        if not isinstance(value, dict):
            skipped.append(SkippedLine(number, f"not a dict but a {type(value).__name__}"))
            continue
        if "control" not in value and "midi" not in value:
            headers.append((number, value))
            acc: Any = value.get("acc")
            header_acc = float(acc) if _is_number(acc) else None
            after_header = True
            continue
        try:
            control = _control(value.get("control"))
            events = _events(value.get("midi"))
        except ValueError as exc:
            skipped.append(SkippedLine(number, str(exc)))
            continue
        records.append(_Record(number, control, events, header_acc, after_header))
        after_header = False
    return records, headers, skipped


def _literal(text: str) -> Any:
    """`ast.literal_eval`, also accepting the bare `nan`/`inf` that Python prints for floats."""
    try:
        tree = ast.parse(text, mode="eval")
    except (SyntaxError, ValueError, MemoryError, RecursionError) as exc:
        raise ValueError(getattr(exc, "msg", None) or type(exc).__name__) from None
    try:
        return ast.literal_eval(_Floats().visit(tree))
    except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError) as exc:
        raise ValueError(str(exc).split("\n")[0] or type(exc).__name__) from None


class _Floats(ast.NodeTransformer):
    """Turns the names `nan` and `inf` into float constants (nothing else is evaluated)."""

    def visit_Name(self, node: ast.Name) -> ast.AST:
        if node.id in ("nan", "inf"):
            return ast.copy_location(ast.Constant(float(node.id)), node)
        return node


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _control(value: Any) -> tuple[float, ...]:
    if not isinstance(value, list | tuple) or not value:
        raise ValueError("'control' is not a non-empty list")
    if not all(_is_number(v) for v in value):
        raise ValueError(f"'control' holds a non-number: {value!r:.80}")
    return tuple(float(v) for v in value)


def _events(value: Any) -> tuple[tuple[int, int, int, int], ...]:
    if not isinstance(value, list | tuple):
        raise ValueError("'midi' is not a list")
    events = []
    for i, item in enumerate(value):
        try:
            message, timestamp = item
            status, note, velocity = message[0], message[1], message[2]
        except (TypeError, ValueError, IndexError, KeyError):
            raise ValueError(
                f"MIDI event {i} is not [[status, note, velocity, 0], timestamp_ms]"
            ) from None
        numbers = (status, note, velocity, timestamp)
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in numbers):
            raise ValueError(f"MIDI event {i} holds a non-integer: {item!r:.80}")
        if not (
            0 <= status <= 255 and 0 <= note <= 127 and 0 <= velocity <= 127 and timestamp >= 0
        ):
            raise ValueError(f"MIDI event {i} is out of range: {item!r:.80}")
        events.append((status, note, velocity, timestamp))
    return tuple(events)


def _sessions(records: list[_Record]) -> list[list[int]]:
    """Record indices per MIDI clock session: a header line or a timestamp going back starts one."""
    sessions: list[list[int]] = []
    latest = -1
    for i, record in enumerate(records):
        times = [e[3] for e in record.events]
        restart = bool(times) and min(times) < latest
        if not sessions or record.after_header or restart:
            sessions.append([])
            latest = -1
        sessions[-1].append(i)
        if times:
            latest = max(latest, max(times))
    return sessions


def _motion_times(params: list[dict[str, float]]) -> tuple[np.ndarray, np.ndarray]:
    """Predicted moveL down + hold + up time and down time per line (0 where not computable)."""
    cycle = np.zeros(len(params))
    down = np.zeros(len(params))
    for i, p in enumerate(params):
        travel = p["distance_m"] + (0.0 if math.isnan(p["depth_m"]) else p["depth_m"])
        try:
            t_down = move_profile(travel, p["down_velocity_mps"], p["acceleration_mps2"]).duration_s
            t_up = move_profile(travel, p["up_velocity_mps"], p["up_acceleration_mps2"]).duration_s
        except (ValueError, TypeError):
            continue  # NaN or non-physical values: no prediction for this line
        hold = 0.0 if math.isnan(p["hold_s"]) else p["hold_s"]
        if math.isfinite(t_down + t_up + hold):
            cycle[i], down[i] = t_down + hold + t_up, t_down
    return cycle, down


def _build_tables(records: list[_Record], layout: Layout) -> tuple[pd.DataFrame, pd.DataFrame, int]:
    params = [layout.params(r.control, r.header_acc) for r in records]
    read_size = max(1, max(len(r.events) for r in records))  # an empty line always drained
    cycle, down = _motion_times(params)
    press_of: dict[int, Press] = {}
    unread: set[int] = set()  # lines whose silence is not proven (no drain line after them)
    order = 0
    sessions = _sessions(records)
    session_of = {}
    for s, members in enumerate(sessions):
        events = []
        for local, i in enumerate(members):
            session_of[i] = s
            for status, note, velocity, t_ms in records[i].events:
                events.append(LogEvent(t_ms, status, note, velocity, local, order))
                order += 1
        presses = group_presses(events)
        drains = [len(records[i].events) < read_size for i in members]
        idx = np.array(members)
        presses, keys = assign_presses(presses, len(members), drains, cycle[idx], down[idx])
        for found, key in zip(presses, keys, strict=True):
            press_of[members[key]] = found
        last_drain = max((k for k, drained in enumerate(drains) if drained), default=-1)
        unread.update(members[k] for k in range(last_drain + 1, len(members)))
    notes = Counter(e.note for p in press_of.values() for e in p.events)
    usual_note = notes.most_common(1)[0][0] if notes else None
    rows = []
    midi_rows = []
    for i, record in enumerate(records):
        press = press_of.get(i)
        row: dict[str, Any] = {"index": i, "source_line": record.line, "session": session_of[i]}
        row.update(_outcome(press, usual_note))
        row["error"] = None
        if press is None and i in unread:
            row["status"], row["error"] = "failed", UNREAD_ERROR
        row["finger"] = layout.finger_of(record.control)
        row.update(params[i])
        rows.append(row)
        if press is not None:
            members = sessions[session_of[i]]
            for e in press.events:
                midi_rows.append({
                    "index": i, "source_line": records[members[e.record]].line, "session": session_of[i],
                    "t_s": e.t_ms / 1000.0, "type": e.kind, "note": e.note, "velocity": e.velocity, "status": e.status,
                })  # fmt: skip
    trials = pd.DataFrame(rows, columns=list(TRIAL_COLUMNS))
    trials["note"] = trials["note"].astype("Int64")
    trials["n_note_on"] = trials["n_note_on"].astype("int64")
    midi = pd.DataFrame(midi_rows, columns=list(MIDI_COLUMNS))
    return trials, midi, len(sessions)


def _outcome(press: Press | None, usual_note: int | None) -> dict[str, Any]:
    """MIDI outcome of one keystroke: silent when no note-on was assigned to it."""
    ons = [e for e in press.events if e.kind == "note_on"] if press else []
    if not ons:
        offs = [e for e in press.events if e.kind == "note_off"] if press else []
        return {
            "status": "silent", "note": offs[0].note if offs else usual_note, "on_velocity": math.nan,
            "off_velocity": float(offs[-1].velocity) if offs else math.nan, "t_on_s": math.nan,
            "t_off_s": offs[-1].t_ms / 1000.0 if offs else math.nan, "midi_hold_s": math.nan, "n_note_on": 0,
        }  # fmt: skip
    assert press is not None
    first = ons[0]
    offs = [e for e in press.events if e.kind == "note_off" and e.t_ms >= first.t_ms]
    t_on = first.t_ms / 1000.0
    t_off = offs[-1].t_ms / 1000.0 if offs else math.nan
    return {
        "status": "ok", "note": first.note, "on_velocity": float(first.velocity),
        "off_velocity": float(offs[-1].velocity) if offs else math.nan, "t_on_s": t_on, "t_off_s": t_off,
        "midi_hold_s": t_off - t_on, "n_note_on": len(ons),
    }  # fmt: skip
