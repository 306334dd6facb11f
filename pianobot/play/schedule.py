"""Fitting one finger's presses into a song's timing: plan rows, arm occupancy, re-strikes.

Each plan row starts at its ideal motion start (onset − predicted lead). Going through the
notes in order, a note may start once the previous played note lets the arm go:

    free = previous start + busy (arm back up + recovery) + lateral move + vacuum change
    free = max(free, previous start + predicted note-off + re-strike margin)   (same key only)

The lateral move starts when the arm is back up, while the released key is still returning (it
rings on its own); only a re-strike of the same key must wait for it to rise past its re-trigger
depth, which is where the piano sends the note-off. When a note would start late the scheduler
shortens the previous hold, then plays the note with a faster stroke (a shorter lead: louder
than asked), then accepts up to `max_late_s`, and only then skips it.
"""

from __future__ import annotations

from typing import Any

import pandas as pd

from pianobot.io.midifile import Note
from pianobot.plan import key_change_s
from pianobot.play.settings import PlaySettings
from pianobot.play.strokes import StrokeTable
from pianobot.spec import RigSpec

# A phrase may change the vacuum only across a rest this many times the rig's settle time:
# the regulator's real settling varies with the size of the step.
VACUUM_BUDGET_FACTOR = 1.25
LOUDER = "louder than asked to keep time"

PLAN_COLUMNS: tuple[str, ...] = (
    "note_index", "pitch", "onset_s", "offset_s", "song_velocity", "target_velocity",
    "vacuum_kpa", "down_velocity_mps", "up_velocity_mps", "acceleration_mps2", "depth_m",
    "distance_m", "hold_s", "predicted_velocity", "predicted_lead_s", "predicted_midi_hold_s",
    "predicted_release_s", "move_s", "vacuum_change_s", "start_s", "busy_s", "late_s", "status",
    "reason",
)


def note_row(i: int, n: Note, target: float, table: StrokeTable, speed: float, hold_cap_s: float,
             reason: str) -> dict[str, Any]:
    """The plan row of note i played at `speed` with `table`'s geometry, hold from its length."""
    g = table.geometry
    hold = min(float(table.arm_hold_for(speed, n.duration_s)), hold_cap_s)
    lead = float(table.lead(speed))
    return {
        "note_index": i, "pitch": n.pitch, "onset_s": n.onset_s, "offset_s": n.offset_s,
        "song_velocity": n.velocity, "target_velocity": float(target),
        "vacuum_kpa": table.vacuum_kpa, "down_velocity_mps": speed,
        "up_velocity_mps": g.up_velocity_mps, "acceleration_mps2": g.acceleration_mps2,
        "depth_m": g.depth_m, "distance_m": g.distance_m, "hold_s": hold,
        "predicted_velocity": float(table.predict_velocity(speed)),
        "predicted_lead_s": lead,
        "predicted_midi_hold_s": float(table.midi_hold(speed, hold)),
        "predicted_release_s": table.release_s(speed, hold),
        "move_s": 0.0, "vacuum_change_s": 0.0, "start_s": n.onset_s - lead,
        "busy_s": table.busy_s(speed, hold), "late_s": 0.0, "status": "play", "reason": reason,
    }


def schedule(frame: pd.DataFrame, tables: dict[float, StrokeTable], settings: PlaySettings,
             rig: RigSpec, *, max_late_s: float | None = None, shorten: bool = True,
             hold_cap_s: float = 2.0) -> pd.DataFrame:
    """Fit the presses one after another (see the module doc); returns a new frame.

    Without tables (the naive planner) holds are never shortened and strokes never changed;
    `shorten=False` keeps holds as planned too.
    """
    out = frame.copy()
    late_limit = settings.max_late_s if max_late_s is None else max_late_s
    vacuum_budget = VACUUM_BUDGET_FACTOR * rig.settle_s.after_vacuum_change_s
    prev: int | None = None
    for i in range(len(out)):
        if prev is None:
            prev = i
            continue
        row = out.iloc[i]
        p = out.iloc[prev]
        same_key = int(row.pitch) == int(p.pitch)
        move = 0.0 if same_key else key_change_s(int(p.pitch), int(row.pitch), rig)
        vac = vacuum_budget if abs(float(row.vacuum_kpa) - float(p.vacuum_kpa)) > 1e-9 else 0.0
        _put(out, i, "move_s", move)
        _put(out, i, "vacuum_change_s", vac)

        margin = settings.restrike_margin_s if same_key else None
        short = _free_s(out.iloc[prev], move + vac, margin) - float(row.start_s)
        # Shortening and speeding up are undone if the note is skipped after all.
        saved = out.iloc[[prev, i]].copy()
        table = tables.get(float(row.vacuum_kpa))
        previous_table = tables.get(float(p.vacuum_kpa))
        if shorten and short > 0 and previous_table is not None:
            # Two passes: for a re-strike the note-off moves with the hold by the hold slope.
            for _ in range(2):
                q = out.iloc[prev]
                if short <= 0 or float(q.hold_s) <= 0:
                    break
                _set_hold(out, prev, max(0.0, float(q.hold_s) - short), previous_table)
                short = _free_s(out.iloc[prev], move + vac, margin) - float(row.start_s)
        free = _free_s(out.iloc[prev], move + vac, margin)
        if short > late_limit and table is not None:
            _speed_up(out, i, table, float(row.onset_s) - free, hold_cap_s)
            short = free - float(out.iloc[i].start_s)
        if short > late_limit + 1e-9:
            out.iloc[[prev, i]] = saved
            _put(out, i, "status", "skip")
            _put(out, i, "reason", (
                f"no time to release and re-strike: the arm is free {short * 1e3:.0f} ms after "
                "this note's motion must start"
            ))
            continue
        if short > 0:
            _put(out, i, "start_s", free)
            _put(out, i, "late_s", short)
            _note(out, i, f"late by {short * 1e3:.0f} ms")
        prev = i
    return out


def _free_s(previous: pd.Series, between_s: float, restrike_margin_s: float | None) -> float:
    """When the arm may start the next press after `previous` (a re-strike when a margin is given)."""
    free = float(previous.start_s) + float(previous.busy_s) + between_s
    release = float(previous.predicted_release_s)
    if restrike_margin_s is not None and release == release:  # NaN: the naive plan predicts none
        free = max(free, float(previous.start_s) + release + restrike_margin_s)
    return free


def _speed_up(frame: pd.DataFrame, i: int, table: StrokeTable, max_lead_s: float, hold_cap_s: float) -> None:
    """Play row i with the slowest stroke whose lead still fits (louder than planned), if any."""
    row = frame.iloc[i]
    speed = table.fastest_lead_for(max_lead_s, float(row.down_velocity_mps))
    if speed is None or speed <= float(row.down_velocity_mps):
        return
    note = Note(int(row.pitch), float(row.onset_s), float(row.offset_s), int(row.song_velocity))
    new = note_row(int(row.note_index), note, float(row.target_velocity), table, speed, hold_cap_s, "")
    for column in ("down_velocity_mps", "hold_s", "predicted_velocity", "predicted_lead_s",
                   "predicted_midi_hold_s", "predicted_release_s", "start_s", "busy_s"):
        _put(frame, i, column, new[column])
    _note(frame, i, f"{LOUDER} ({new['predicted_velocity']:.1f} for {float(row.target_velocity):.1f})")


def _set_hold(frame: pd.DataFrame, i: int, hold_s: float, table: StrokeTable) -> None:
    """Shorten row i's arm hold and update what depends on it (MIDI hold, note-off, busy time)."""
    speed = float(frame.iloc[i].down_velocity_mps)
    _put(frame, i, "hold_s", hold_s)
    _put(frame, i, "predicted_midi_hold_s", float(table.midi_hold(speed, hold_s)))
    _put(frame, i, "predicted_release_s", table.release_s(speed, hold_s))
    _put(frame, i, "busy_s", table.busy_s(speed, hold_s))


def _note(frame: pd.DataFrame, i: int, text: str) -> None:
    old = str(frame["reason"].iloc[i])
    _put(frame, i, "reason", f"{old}; {text}" if old else text)


def _put(frame: pd.DataFrame, i: int, column: str, value: Any) -> None:
    """Set one cell of row position i."""
    frame.loc[frame.index[i], column] = value

