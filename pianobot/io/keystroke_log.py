"""Reader of the study's old keystroke logs: one Python-literal dict per line.

    {'control': [60, 45, 0.5, 0.03, 0.04, 0.05, 0], 'midi': [[[144, 57, 1, 0], 468620], ...]}
    {'group': 0, 'order': 0, 'note': 'F', 'move_vel': 0.24, ..., 'midi': [...]}

Lines are read as a stream (`log_lines`); dicts without `control`/`midi` are headers (metadata
that also starts a new MIDI clock session); malformed lines are reported (line number, reason)
and the rest is imported. Positional `control` lists are decoded by a layout (the study's, chosen
automatically, or one the user declares: `keystroke_layouts`, `layout_file`); named keys by
`named_keys`. MIDI events are grouped into presses and each press is given to the keystroke line
the evidence says it belongs to (`keystroke_sessions`, `keystroke_assign`).
`read_keystroke_log(path)` returns a `KeystrokeLog`.
"""

from __future__ import annotations

from array import array
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pianobot.errors import InputError
from pianobot.io.keystroke_layouts import (
    LAYOUT_CHOICES,
    LAYOUTS,
    ControlLayout,
    choose_layout,
    declared_layout,
    layouts_tried,
)
from pianobot.io.keystroke_records import LogRecords
from pianobot.io.keystroke_sessions import assign_events
from pianobot.io.layout_file import load_layout_file
from pianobot.io.log_lines import LogLines, SkippedLine, parse_lines
from pianobot.io.named_keys import DEFAULT_NOTE_OCTAVE, named_records
from pianobot.io.source import text_lines
from pianobot.progress import NO_PROGRESS, Progress
from pianobot.spec.parameters import FINGER_ENVELOPES

__all__ = ["KeystrokeLog", "SkippedLine", "read_keystroke_log"]

# A session of the study logged a few hundred keystrokes; a million lines is a week of
# non-stop pressing. Checked as the lines stream in, so memory stays bounded either way.
MAX_LOG_LINES = 1_000_000


@dataclass(frozen=True)
class KeystrokeLog:
    """A parsed log.

    `trials`: one row per keystroke line (pianobot column names; `t_on_s`/`t_off_s` are seconds
    on the session's MIDI clock, i.e. since the MIDI init of that script run), with the
    assignment of its MIDI events (`read_line`, `moved_from_line`, `assignment`,
    `assignment_evidence`). `midi`: every note event with the keystroke `index` it was assigned
    to (-1: none) and the `source_line` that printed it. `header`: the first header dict;
    `headers`: all of them with their line numbers. `assignment`: how events were assigned
    (read size, per-session constants, counts, presses that belong to no line).
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
    assignment: dict[str, Any] = field(default_factory=dict)
    columns: dict[str, str] = field(default_factory=dict)  # named-key logs: key -> column
    notes: str = ""  # how notes and the finger were read (stated conventions)


def read_keystroke_log(
    path: Path | str,
    layout: str = "auto",
    *,
    columns: list[str] | None = None,
    layout_file: Path | str | None = None,
    finger: str | None = None,
    note_octave: int = DEFAULT_NOTE_OCTAVE,
    progress: Progress = NO_PROGRESS,
) -> KeystrokeLog:
    """Parse a dict-per-line keystroke log.

    Args:
        path: the log file.
        layout: "auto", "soft-2022", "rigid-2022", or a concrete layout name (see
            `keystroke_layouts.LAYOUT_CHOICES`), for positional logs.
        columns: the positional layout declared as column names (instead of `layout`).
        layout_file: a YAML layout file (instead of `layout`).
        finger: "soft" or "rigid" when the log does not say (overrides the inference).
        note_octave: the octave of note letters without one (4: C–B = MIDI 60–71).
        progress: where to report reading and assignment.

    Raises:
        InputError: unknown layout; the file is missing, empty, binary or holds no keystroke line;
            no layout fits its control lists.
    """
    path = Path(path)
    where = str(path)
    declared = _declared(layout, columns, layout_file, finger)
    if finger is not None and finger not in ("soft", "rigid"):
        raise InputError(f"finger should be soft or rigid, got {finger!r}", "--finger")
    size = path.stat().st_size if path.is_file() else None
    parsed = parse_lines(_bounded(text_lines(path, "a text log"), where), progress, size)
    if not len(parsed):
        reasons = "; ".join(f"line {s.line}: {s.reason}" for s in parsed.skipped[:3])
        raise InputError(
            "no keystroke line ({'control': [...], 'midi': [...]} or named keys with 'midi') found"
            + (f": {reasons}" if reasons else ""),
            where,
        )
    _refuse_systematic_skips(parsed, where)
    if parsed.n_named > parsed.n_positional:
        records, layout_name, notes_text = _named(parsed, note_octave, finger)
    else:
        records, layout_name = _positional(parsed, layout, declared, finger, where)
        notes_text = ""
    if parsed.ignored:
        ignored = ", ".join(f"{key} ({count} lines)" for key, count in parsed.ignored.items())
        notes_text = "; ".join(t for t in (notes_text, f"keys besides control and midi ignored: {ignored}") if t)
    trials, midi, summary = assign_events(records, progress)
    skipped = sorted(parsed.skipped + records.skipped, key=lambda s: s.line)
    fingers = Counter(trials["finger"])
    return KeystrokeLog(
        path=path,
        layout=layout_name,
        finger=fingers.most_common(1)[0][0] if fingers else "unknown",
        trials=trials,
        midi=midi,
        skipped=tuple(skipped),
        header=parsed.headers[0][1] if parsed.headers else {},
        headers=tuple(parsed.headers),
        n_sessions=int(summary["sessions"]),
        assignment=summary,
        columns=records.columns,
        notes=notes_text,
    )


#: Skipped lines outnumber the records and this share of them fails for one reason: refused.
SYSTEMATIC_SKIP_SHARE = 0.9


def _refuse_systematic_skips(parsed: LogLines, where: str) -> None:
    """InputError when most lines fail for one and the same reason (a format this reader does
    not know, e.g. MIDI timestamps in seconds): importing the rest would keep only the lines the
    problem spared (there, the silent keystrokes), a biased session. Lines that fail for
    different reasons (a damaged file) are reported and the rest imported."""
    skipped = parsed.skipped
    if len(skipped) <= len(parsed):
        return
    reason, count = Counter(s.reason.split(":")[0] for s in skipped).most_common(1)[0]
    if count < SYSTEMATIC_SKIP_SHARE * len(skipped):
        return
    first = next(s for s in skipped if s.reason.split(":")[0] == reason)
    raise InputError(f"{len(skipped)} of {len(skipped) + len(parsed)} keystroke lines fail alike (line {first.line}: "
                     f"{first.reason}); the log is not imported in part", where)


def _bounded(lines: Iterator[tuple[int, str]], where: str) -> Iterator[tuple[int, str]]:
    """The lines, refused (InputError) once there are more than MAX_LOG_LINES."""
    for number, text in lines:
        if number > MAX_LOG_LINES:
            raise InputError(f"has more than {MAX_LOG_LINES:,} lines; a keystroke log is read up "
                             "to that many (split it into sessions)", where)
        yield number, text


def _declared(
    layout: str, columns: list[str] | None, layout_file: Path | str | None, finger: str | None
) -> ControlLayout | None:
    if columns is not None and layout_file is not None:
        raise InputError("give either --columns or --layout-file, not both", "--columns")
    if (columns is not None or layout_file is not None) and layout != "auto":
        raise InputError(
            "--layout names a known layout; a declared one (--columns, --layout-file) replaces it",
            "--layout",
        )
    if columns is not None:
        return declared_layout(columns, finger or "unknown")
    if layout_file is not None:
        return load_layout_file(layout_file)
    if layout not in LAYOUT_CHOICES:
        raise InputError(
            f"layout should be one of {sorted(LAYOUT_CHOICES)}, got {layout!r}", "--layout"
        )
    return None


def _positional(
    parsed: LogLines, choice: str, declared: ControlLayout | None, finger: str | None, where: str
) -> tuple[LogRecords, str]:
    counts = (
        np.frombuffer(parsed.n_control, dtype=np.int32).astype(np.int64)
        if len(parsed.n_control)
        else np.zeros(0, np.int64)
    )
    is_positional = _kinds(parsed)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    values = np.frombuffer(parsed.control, dtype=np.float64) if len(parsed.control) else np.zeros(0)
    lengths = Counter(counts.tolist())
    lines = np.frombuffer(parsed.line, dtype=np.int64)[is_positional]
    chosen = declared
    if chosen is None:
        plausible = {}
        for name in LAYOUT_CHOICES[choice]:
            n = len(LAYOUTS[name].slots)
            rows = _rows(values, offsets, counts, n)
            plausible[name] = int(LAYOUTS[name].plausible(rows).sum()) if rows.size else 0
        chosen = choose_layout(choice, dict(lengths), plausible)
    if chosen is None:
        n, count = lengths.most_common(1)[0]
        first = int(lines[np.flatnonzero(counts == n)[0]])
        raise InputError(
            f"line {first}: {n} control values ({count} such lines); no known layout has {n} "
            f"(tried {layouts_tried(choice)}); declare the columns with --columns a,b,... "
            "or --layout-file FILE",
            where,
        )
    n = len(chosen.slots)
    fits = counts == n
    if not fits.any():
        m, count = lengths.most_common(1)[0]
        raise InputError(
            f"line {int(lines[0])}: {m} control values ({count} such lines), but layout "
            f"{chosen.name} has {n} columns ({', '.join(chosen.slots)})",
            where,
        )
    skipped = [
        SkippedLine(
            int(lines[i]), f"control has {int(counts[i])} values, layout {chosen.name} expects {n}"
        )
        for i in np.flatnonzero(~fits)
    ]
    skipped += _other_kind(parsed, is_positional, "a named-key line in a log of control lists")
    control = _rows(values, offsets, counts, n)
    parsed.control = array("d")  # the flat values are rows now: free them before the assignment
    header_acc = np.frombuffer(parsed.header_acc, dtype=np.float64)[is_positional][fits]
    params = chosen.table(control, header_acc)
    fingers = chosen.fingers(control)
    if finger is not None:
        fingers[fingers == chosen.finger] = finger
    notes = params.pop("note").fillna(-1).to_numpy(dtype=np.int64) if "note" in params else None
    extra = params[list(chosen.extra_slots)]
    params = params.drop(columns=list(chosen.extra_slots))
    records = LogRecords.build(
        parsed,
        np.flatnonzero(is_positional)[fits],
        params,
        fingers,
        notes,
        extra,
        pd.DataFrame(index=range(len(params))),
        chosen.up_travel,
        skipped,
    )
    return records, chosen.name


def _named(parsed: LogLines, note_octave: int, finger: str | None) -> tuple[LogRecords, str, str]:
    is_named = ~_kinds(parsed)
    index = np.flatnonzero(is_named)
    if index.size == len(parsed):  # the usual case: no control-list lines mixed in
        named = parsed.named
    else:
        named = {key: [values[i] for i in index] for key, values in parsed.named.items()}
    found = named_records(named, note_octave)
    parsed.named = {}  # the raw values are columns now: free them before the assignment
    lines = np.frombuffer(parsed.line, dtype=np.int64)[index]
    skipped = [SkippedLine(int(lines[i]), reason) for i, reason in sorted(found.bad_lines.items())]
    skipped += _other_kind(parsed, is_named, "a control-list line in a log of named keys")
    keep = np.ones(index.size, dtype=bool)
    keep[list(found.bad_lines)] = False
    chosen_finger, finger_text = _named_finger(found.params[keep], finger)
    fingers = np.full(int(keep.sum()), chosen_finger, dtype=object)
    params = found.params[keep].reset_index(drop=True)
    records = LogRecords.build(
        parsed,
        index[keep],
        params,
        fingers,
        found.note[keep],
        found.extra[keep].reset_index(drop=True),
        found.sequence[keep].reset_index(drop=True),
        "depth" if found.is_sequence_script else "distance+depth",
        skipped,
        columns=found.columns,
    )
    octave_text = (
        f"note letters without an octave are octave {note_octave} "
        f"(C{note_octave} = MIDI {12 * (note_octave + 1)}; middle C is C4 = 60)"
    )
    return records, "named-keys", f"{octave_text}; {finger_text}"


def _named_finger(params: pd.DataFrame, finger: str | None) -> tuple[str, str]:
    """The finger of a named-key log: given, or inferred from its vacuum or its press depths."""
    if finger is not None:
        return finger, f"finger {finger} (given)"
    if params["vacuum_kpa"].notna().any():
        return "soft", "finger soft (the log records a vacuum)"
    depth = params["depth_m"].dropna()
    if depth.empty:
        return "unknown", "finger unknown (no vacuum, no depth logged; give --finger)"
    median = float(depth.median())
    for name, limits in FINGER_ENVELOPES.items():
        if limits["depth_m"].contains(median):
            return name, (
                f"finger {name} (inferred: median press depth {median * 1000:.1f} mm lies in the "
                f"{name} finger's depth range; give --finger to override)"
            )
    return (
        "unknown",
        f"finger unknown (median depth {median * 1000:.1f} mm fits no finger; give --finger)",
    )


def _kinds(parsed: LogLines) -> np.ndarray:
    """Per record: True for a control-list record, False for a named-key one."""
    out = np.zeros(len(parsed), dtype=bool)
    if parsed.n_positional and not parsed.n_named:
        out[:] = True
    elif parsed.n_positional:
        named_any = np.zeros(len(parsed), dtype=bool)
        for column in parsed.named.values():
            named_any |= np.array([v is not None for v in column])
        out = ~named_any
    return out


def _rows(values: np.ndarray, offsets: np.ndarray, counts: np.ndarray, n: int) -> np.ndarray:
    """Control lists of length n as a (lines, n) array."""
    starts = offsets[:-1][counts == n]
    if not starts.size:
        return np.zeros((0, n))
    rows: np.ndarray = values[starts[:, None] + np.arange(n)[None, :]]
    return rows


def _other_kind(parsed: LogLines, kept: np.ndarray, reason: str) -> list[SkippedLine]:
    lines = np.frombuffer(parsed.line, dtype=np.int64)
    return [SkippedLine(int(lines[i]), reason) for i in np.flatnonzero(~kept)]
