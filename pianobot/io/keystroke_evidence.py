"""The evidence for a moved or doubtful press, in words, for the trials' `assignment_evidence`."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from pianobot.io.keystroke_assign import Lines, Presses, SessionAssignment

IntArray = npt.NDArray[np.int64]


def backlog_origins(read_line: IntArray, line: IntArray) -> IntArray:
    """Per press: the press where its backlog last grew (lag = read line - line)."""
    lag = read_line - line
    origin = np.zeros(line.size, dtype=np.int64)
    for i in range(1, line.size):
        grew = line[i - 1] < 0 or line[i] < 0 or lag[i - 1] < lag[i]
        origin[i] = i if grew else origin[i - 1]
    return origin


def move_evidence(
    i: int,
    result: SessionAssignment,
    presses: Presses,
    lines: Lines,
    file_line: IntArray,
    n_events: IntArray,
    read_size: int,
    j: int,
) -> str:
    """Why press i left its read line, in words: what fits where, and where the backlog began
    (press j, where its backlog last grew)."""
    k, r = int(result.line[i]), int(presses.read_line[i])
    parts = [f"printed on line {file_line[r]}, belongs to line {file_line[k]}"]
    note = int(presses.note[i])
    if note >= 0 and lines.note[k] == note and lines.note[r] >= 0 and lines.note[r] != note:
        parts.append(
            f"its note {note} is the key of line {file_line[k]}, not of line {file_line[r]} ({lines.note[r]})"
        )
    own = float(result.own_line_cost[i])
    if math.isfinite(own):
        parts.append(
            f"keeping it on line {file_line[r]} fits the timestamps and keys worse by {own:.1f} (squared SDs)"
        )
    else:
        parts.append(
            f"line {file_line[r]} cannot hold it (the presses printed after it need the lines up to it)"
        )
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


def unassigned_text(reason: str, presses: Presses, i: int, file_line: IntArray) -> str:
    if not reason.startswith("note:"):
        return reason
    first = int(reason.split(":")[1])
    return (
        f"its note {int(presses.note[i])} is the key of no line it could belong to (lines "
        f"{file_line[first]}–{file_line[presses.read_line[i]]}): a keystroke the log never wrote, "
        "e.g. one cut short by a connection drop"
    )


def doubt_text(
    t_s: float, file_line: IntArray, read: int, k: int, alt: int, margin: float, capped: bool
) -> str:
    if capped:
        return (
            f"MIDI outcome undecided: the press at {t_s:.3f} s (printed on line {file_line[read]}) lies at "
            "the deepest backlog considered; its keystroke may be further back"
        )
    other = f"line {file_line[alt]}" if alt >= 0 else "another line"
    return (
        f"MIDI outcome undecided: the press at {t_s:.3f} s (printed on line {file_line[read]}) fits "
        f"line {file_line[k]} and {other} almost equally (cost difference {margin:.1f})"
    )
