"""Reader of a UR arm log: the file ur_rtde's `RTDEReceiveInterface.startFileRecording` writes.

Layout: one header line naming the recorded RTDE outputs, vectors spread over `<name>_0` …
`<name>_5` (`timestamp,actual_TCP_pose_0,…,actual_TCP_pose_5,…`), then one row per controller
cycle (125 Hz on a CB3 UR5, 500 Hz on an e-Series). ur_rtde separates the fields with commas;
the recorder of UR's own RTDE client library (`record.py`) writes the same header with spaces,
and both are read, as is a spreadsheet's re-save with semicolons (and decimal commas), quoted
or capitalised names; lines starting with `#` are notes, not data. `timestamp` is the controller's clock (seconds since it started);
`actual_TCP_pose_2` is the tool point's height in the robot base frame (metres, up).

What is kept: the time from the log's first row, the tool point's downward displacement
(−z, for pianobot's downward-positive x0) and, when recorded, the controller's target pose
(`target_TCP_pose_2`: the commanded profile). A last row cut short (the recording stopped
mid-line) is dropped and counted; a row that repeats the one before's timestamp (a recorder
that wrote the same controller state twice) is dropped and counted; any other row that is not
numbers, or a timestamp that goes back, is an error naming its line.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.errors import InputError
from pianobot.io.mocap_segment import rest_level_before
from pianobot.io.source import read_input_bytes

FloatArray = npt.NDArray[np.float64]
KIND = "a UR arm log (ur_rtde file recording)"
TIME, ACTUAL_Z, TARGET_Z = "timestamp", "actual_TCP_pose_2", "target_TCP_pose_2"
MIN_ROWS = 10


@dataclass(frozen=True)
class ArmLog:
    """A UR arm log on its own clock: `t_s` from the first row, displacements downward (m)."""

    path: Path
    t_s: FloatArray
    down_m: FloatArray  # actual tool point, −z
    target_down_m: FloatArray | None  # the controller's target, −z (None when not recorded)
    first_timestamp_s: float  # the controller time of the first row
    rate_hz: float
    dropped_last_row: bool
    repeated_rows: int = 0  # rows with the timestamp of the row before them, dropped

    def meta(self) -> dict[str, object]:
        return {
            "file": self.path.name,
            "format": "ur-rtde-csv",
            "rows": int(self.t_s.size),
            "rate_hz": round(self.rate_hz, 3),
            "first_timestamp_s": self.first_timestamp_s,
            "target_recorded": self.target_down_m is not None,
            "dropped_last_row": self.dropped_last_row,
            "repeated_rows": self.repeated_rows,
        }


def read_arm_log(path: Path | str) -> ArmLog:
    """Parse an arm log (see the module docstring).

    Raises:
        InputError: naming the file (and line): not such a log, a missing `timestamp` or
            `actual_TCP_pose_2` column, a row that is not numbers, time that does not increase,
            or fewer than MIN_ROWS rows.
    """
    path = Path(path)
    where = str(path)
    text = read_input_bytes(path, KIND).decode("utf-8", errors="replace").lstrip("\ufeff")
    lines = text.splitlines()
    # A note a person wrote above the header or between rows ("# robot 2, tool v3") is not data.
    header_at = next((i for i, line in enumerate(lines) if line.strip() and not _comment(line)), None)
    if header_at is None:
        raise InputError("the file is empty", where)
    split = _splitter(lines[header_at])
    names = split(lines[header_at])
    lowered = [name.lower() for name in names]  # a spreadsheet's re-save may capitalise the names
    missing = [name for name in (TIME, ACTUAL_Z) if name.lower() not in lowered]
    if missing:
        shown = ", ".join(names[:6]) + (", …" if len(names) > 6 else "")
        raise InputError(f"not {KIND}: no column {' or '.join(missing)} in the header ({shown})",
                         f"{where}:{header_at + 1}")
    wanted = [lowered.index(TIME.lower()), lowered.index(ACTUAL_Z.lower())]
    if TARGET_Z.lower() in lowered:
        wanted.append(lowered.index(TARGET_Z.lower()))
    rows: list[list[float]] = []
    body = [(n, line) for n, line in enumerate(lines[header_at + 1:], start=header_at + 2)
            if line.strip() and not _comment(line)]
    dropped = False
    for k, (number, line) in enumerate(body):
        fields = split(line)
        values = _numbers(fields, wanted, len(names))
        if values is None:
            if k == len(body) - 1 and len(fields) < len(names):
                dropped = True  # the recording stopped mid-row
                break
            raise InputError(f"expected {len(names)} numbers as in the header, got {line.strip()[:60]!r}",
                             f"{where}:{number}")
        rows.append(values)
    if len(rows) < MIN_ROWS:
        raise InputError(f"only {len(rows)} rows of arm samples (need at least {MIN_ROWS})", where)
    table = np.asarray(rows, dtype=np.float64)
    steps = np.diff(table[:, 0])
    if (steps < 0).any():
        bad = int(np.argmax(steps < 0))
        raise InputError(f"the timestamp goes back ({table[bad, 0]:.6f} then {table[bad + 1, 0]:.6f})",
                         f"{where}:{body[bad + 1][0]}")
    repeated = np.concatenate([[False], steps == 0])
    table = table[~repeated]
    if table.shape[0] < MIN_ROWS:
        raise InputError(f"only {table.shape[0]} rows of arm samples with distinct timestamps (need at least "
                         f"{MIN_ROWS})", where)
    stamps = table[:, 0]
    target = -table[:, 2] if table.shape[1] > 2 else None
    return ArmLog(path, stamps - stamps[0], -table[:, 1], target, float(stamps[0]),
                  1.0 / float(np.median(np.diff(stamps))), dropped, int(repeated.sum()))


def _comment(line: str) -> bool:
    return line.lstrip().startswith("#")


def _splitter(header: str) -> Callable[[str], list[str]]:
    """Comma-separated (ur_rtde), whitespace-separated (UR's record.py) or semicolon-separated
    fields (a spreadsheet's re-save, whose numbers may then have decimal commas); quotes around
    a field are dropped."""
    if ";" in header:
        pattern, decimal_comma = re.compile(r"\s*;\s*"), True
    elif "," in header:
        pattern, decimal_comma = re.compile(r"\s*,\s*"), False
    else:
        pattern, decimal_comma = re.compile(r"\s+"), False

    def split(line: str) -> list[str]:
        fields = [f.strip().strip("\"'") for f in pattern.split(line.strip())]
        return [f.replace(",", ".") for f in fields] if decimal_comma else fields

    return split


def _numbers(fields: list[str], wanted: list[int], width: int) -> list[float] | None:
    """The wanted fields as finite floats, or None when the row is not one of the header's width
    (a row that ends in one empty field more, a trailing separator, is of its width)."""
    if len(fields) == width + 1 and not fields[-1]:
        fields = fields[:-1]
    if len(fields) != width:
        return None
    try:
        values = [float(fields[i]) for i in wanted]
    except ValueError:
        return None
    return values if all(math.isfinite(v) for v in values) else None


def arm_samples(log: ArmLog, shift_s: float, trial_ids: list[str], starts_s: FloatArray, ends_s: FloatArray,
                pre_s: float, post_s: float) -> pd.DataFrame:
    """The log's samples per trial (source "arm"): t_s from each trial's start, x0_m from the rest
    level before it; `shift_s` puts the log on the trials' clock (trial time = log time − shift)."""
    t = log.t_s - shift_s
    pieces = []
    for trial_id, start, end in zip(trial_ids, starts_s, ends_s, strict=True):
        window = (t >= start - pre_s) & (t <= end + post_s)
        if not (np.isfinite(start) and window.any()):
            continue
        first = int(np.argmax(t >= start)) if (t >= start).any() else t.size - 1
        pieces.append(pd.DataFrame({"trial_id": trial_id, "source": "arm", "t_s": t[window] - start,
                                    "x0_m": log.down_m[window] - rest_level_before(t, log.down_m, first)}))
    if not pieces:
        return pd.DataFrame(columns=["trial_id", "source", "t_s", "x0_m"])
    return pd.concat(pieces, ignore_index=True)
