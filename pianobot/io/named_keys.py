"""Logs whose lines name their values: `{'group': 0, 'order': 3, 'note': 'G', 'down_vel': ..., 'midi': [...]}`.

Known keys become pianobot's column names (units in the names; the spec's parameter table for
the parameters, `spec.parameters`); every other key is kept as an extra column under its own
name (prefixed `log_` where that would clash or is not a plain name), never dropped.

| key in the log | column | meaning |
|---|---|---|
| group | sequence_id | sequence number (the study's sequence models) |
| order | sequence_order | position of the keystroke in its sequence (0 first) |
| note | note | the key: a MIDI number, or a letter C–B with optional ♯/♭ (`#`, `b`) and octave |
| down_vel, up_vel, vel | down_velocity_mps, up_velocity_mps (vel: both) | moveL speeds, m/s |
| down_acc, acc | acceleration_mps2 | moveL acceleration of the press, m/s² |
| up_acc | up_acceleration_mps2 | acceleration of the upward move, m/s² |
| move_vel, move_acc | move_velocity_mps, move_acceleration_mps2 | the sideways move to the key |
| distance | distance_m | hover height of the fingertip above the key, m |
| press_depth, depth | depth_m | press depth below the key surface, m |
| hold_time, hold | hold_s | hold at the bottom, s |
| angle, finger_angle | finger_angle_deg | finger inclination, degrees |
| vacuum, pressure | vacuum_kpa | finger vacuum; a positive value is a magnitude (60 = -60 kPa gauge) |

pianobot's own column names are accepted as they are. Note letters without an octave are in
octave `note_octave` of scientific pitch notation, where middle C is C4 = MIDI 60: with the
default 4, C–B are MIDI 60–71 (the study's sequence log). An explicit octave (`C#5`, `Bb3`)
overrides it.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from pianobot.errors import InputError
from pianobot.io.keystroke_layouts import (
    COLUMN_ALIASES,
    PARAMETER_SLOTS,
    RIGID_STIFFNESS_CODE,
    round_grid_array,
)
from pianobot.plan.trial import SEQUENCE_COLUMNS
from pianobot.spec.parameters import PARAMETERS, missing_value

DEFAULT_NOTE_OCTAVE = 4  # scientific pitch notation: middle C = C4 = MIDI 60
KEY_COLUMNS = COLUMN_ALIASES
NUMERIC_COLUMNS = PARAMETER_SLOTS
_OWN = {*NUMERIC_COLUMNS, *SEQUENCE_COLUMNS, "note", "velocity_mps"}
_PITCH = {"C": 0, "D": 2, "E": 4, "F": 5, "G": 7, "A": 9, "B": 11}
_NOTE_NAME = re.compile(r"^\s*([A-Ga-g])\s*([#♯b♭]*)\s*(-?\d+)?\s*$")
_RESERVED = {
    "index",
    "source_line",
    "session",
    "status",
    "finger",
    "trial_id",
    "attempt",
    "run_id",
    "on_velocity",
    "off_velocity",
    "t_on_s",
    "t_off_s",
    "midi_hold_s",
    "n_note_on",
    "error",
}


@dataclass(frozen=True)
class NamedRecords:
    """Named-key records as columns: parameters, sequence columns, notes and extra columns."""

    params: pd.DataFrame  # NUMERIC_COLUMNS (NaN where not logged)
    note: np.ndarray  # MIDI note of each line (-1 where not logged)
    sequence: pd.DataFrame  # sequence_id, sequence_order (nullable Int64), when logged
    extra: pd.DataFrame  # unknown keys under their column names
    columns: dict[str, str]  # key in the log -> column
    bad_lines: dict[int, str]  # record index -> why it cannot be imported
    is_sequence_script: bool  # the study's sequence script: it rose by the press depth only


def note_number(value: Any, octave: int = DEFAULT_NOTE_OCTAVE) -> int:
    """MIDI number of a note given as a number or a name (`'G'`, `'F#'`, `'Bb3'`).

    Raises ValueError naming the bad value.
    """
    if isinstance(value, bool):
        raise ValueError(f"note {value!r} is not a note")
    if isinstance(value, int | float) and math.isfinite(value) and float(value).is_integer():
        number = int(value)
    elif isinstance(value, str) and (match := _NOTE_NAME.match(value)):
        letter, accidentals, given = match.groups()
        shift = sum(1 if a in "#♯" else -1 for a in accidentals)
        number = (
            12 * ((int(given) if given is not None else octave) + 1)
            + _PITCH[letter.upper()]
            + shift
        )
    else:
        raise ValueError(f"note {value!r} is neither a MIDI number nor a note name like 'C', 'F#4'")
    if not 0 <= number <= 127:
        raise ValueError(f"note {value!r} is MIDI {number}, outside 0..127")
    return number


def named_records(
    named: dict[str, list[Any]], note_octave: int = DEFAULT_NOTE_OCTAVE
) -> NamedRecords:
    """Turn the named-key columns of a log into pianobot columns (module docstring)."""
    if not -1 <= note_octave <= 9:
        raise InputError(
            f"octave should be in -1..9 (middle C is C4), got {note_octave}", "--note-octave"
        )
    n = len(next(iter(named.values()))) if named else 0
    bad: dict[int, str] = {}
    columns: dict[str, str] = {}
    params = pd.DataFrame({name: np.full(n, np.nan) for name in NUMERIC_COLUMNS})
    extra: dict[str, list[Any]] = {}
    sequence: dict[str, Any] = {}
    notes = np.full(n, -1, dtype=np.int64)
    for key, values in named.items():
        column = KEY_COLUMNS.get(key, key if key in _OWN else None)
        if column is None:
            name = (
                key
                if key.isidentifier() and key not in _RESERVED and key not in _OWN
                else f"log_{_slug(key)}"
            )
            columns[key] = name
            extra[name] = values
            continue
        columns[key] = column
        if column == "note":
            for i, value in enumerate(values):
                if value is None:
                    continue
                try:
                    notes[i] = np.int64(note_number(value, note_octave))
                except ValueError as exc:
                    bad.setdefault(i, str(exc))
            continue
        numbers = _numbers(values, key, bad)
        if column in SEQUENCE_COLUMNS:
            whole = np.isfinite(numbers) & (numbers == np.round(numbers))
            for j in np.flatnonzero(np.isfinite(numbers) & ~whole):
                bad.setdefault(int(j), f"{key!r} is not a whole number: {values[j]!r}")
            sequence[column] = pd.array(
                [int(v) if w else None for v, w in zip(numbers, whole, strict=True)], dtype="Int64"
            )
        elif column == "velocity_mps":
            for target in ("down_velocity_mps", "up_velocity_mps"):
                params[target] = np.where(np.isfinite(params[target]), params[target], numbers)
        elif column == "vacuum_kpa":
            params[column] = np.where(numbers == RIGID_STIFFNESS_CODE, np.nan, -np.abs(numbers))
        else:
            params[column] = numbers
    logged = set(columns.values())
    if "velocity_mps" not in logged:  # (`vel` gave both speeds)
        for name in NUMERIC_COLUMNS:  # not logged: follows what the table says (up ← down)
            if name not in logged and name in PARAMETERS and PARAMETERS[name].follows is not None:
                params[name] = missing_value(name, {c: params[c] for c in params.columns})
    params = params.apply(lambda c: round_grid_array(c.to_numpy(dtype=np.float64)))
    keys = set(named)
    return NamedRecords(
        params=params,
        note=notes,
        sequence=pd.DataFrame(sequence, index=range(n)),
        extra=pd.DataFrame({k: _extra_column(v) for k, v in extra.items()}, index=range(n)),
        columns=columns,
        bad_lines=bad,
        is_sequence_script={"group", "order", "press_depth", "up_vel"} <= keys,
    )


def _numbers(values: list[Any], key: str, bad: dict[int, str]) -> np.ndarray:
    out = np.full(len(values), np.nan)
    for i, value in enumerate(values):
        if value is None:
            continue
        if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value):
            out[i] = float(value)
        else:
            bad.setdefault(i, f"{key!r} should be a number, got {value!r:.40}")
    return out


def _extra_column(values: list[Any]) -> Any:
    """A column Parquet can store: numbers as floats, texts as strings, a mix as texts."""
    present = [v for v in values if v is not None]
    if all(isinstance(v, bool) for v in present):
        return pd.array(values, dtype="boolean")
    if all(isinstance(v, int | float) and not isinstance(v, bool) for v in present):
        return np.array([np.nan if v is None else float(v) for v in values])
    return pd.array([None if v is None else str(v) for v in values], dtype="string")


def _slug(key: str) -> str:
    return re.sub(r"\W+", "_", key).strip("_").lower() or "key"
