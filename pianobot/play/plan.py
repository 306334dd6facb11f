"""The model-based planner: melody notes in, one press per note out, with timing and flags.

Per note the planner chooses, from the model's tabulated strokes (`StrokeTable`):

- loudness: the down velocity whose predicted on-velocity equals the note's target (the song's
  velocity mapped onto the reachable range, see `DynamicsMap`), at the phrase's vacuum level;
- duration: the arm hold whose predicted note-on → note-off time equals the note's length;
- timing: motion start = onset − predicted lead (motion start → note-on); the lateral move to
  the key comes before that and must fit after the previous press and its recovery.

When a note cannot start on time, the previous note's hold is shortened first; a note still
later than `max_late_s` is skipped and reported with the reason (so the notes after it stay in
time) rather than dragging the rest of the song late.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from pianobot.analysis.predictors import StrokePredictor
from pianobot.errors import InputError
from pianobot.io.midifile import Note
from pianobot.plan import key_change_s
from pianobot.play.dynamics import DynamicsMap, DynamicsMode
from pianobot.play.settings import PlaySettings
from pianobot.play.strokes import StrokeTable, busy_s
from pianobot.spec import RigSpec

# A phrase may change the vacuum only across a rest this many times the rig's settle time:
# the regulator's real settling varies with the size of the step.
VACUUM_BUDGET_FACTOR = 1.25

PLAN_COLUMNS: tuple[str, ...] = (
    "note_index", "pitch", "onset_s", "offset_s", "song_velocity", "target_velocity",
    "vacuum_kpa", "down_velocity_mps", "up_velocity_mps", "acceleration_mps2", "depth_m",
    "distance_m", "hold_s", "predicted_velocity", "predicted_lead_s", "predicted_midi_hold_s",
    "move_s", "vacuum_change_s", "start_s", "busy_s", "late_s", "status", "reason",
)


@dataclass(frozen=True)
class Plan:
    """A performance plan: one row per melody note (`PLAN_COLUMNS`), song time in seconds.

    `status` is "play" or "skip"; `reason` says why a note is skipped, late or clipped.
    `start_s` is the planned motion start in song time (it may be negative: the first press
    starts before the song's time zero by its lead).
    """

    planner: str  # "model" | "naive"
    notes: pd.DataFrame
    settings: PlaySettings
    dynamics: DynamicsMap | None = None
    tables: dict[float, StrokeTable] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()

    @property
    def played(self) -> pd.DataFrame:
        return self.notes[self.notes["status"] == "play"]

    def summary(self) -> dict[str, Any]:
        """Counts and the mapping, for JSON output and run.json."""
        frame = self.notes
        return {
            "planner": self.planner,
            "notes": int(len(frame)),
            "planned": int((frame["status"] == "play").sum()),
            "skipped": int((frame["status"] == "skip").sum()),
            "late": int((frame["late_s"] > 0).sum()),
            "dynamics": None if self.dynamics is None else self.dynamics.to_dict(),
            "reachable_by_vacuum": {
                f"{k:g}": list(t.velocity_range) for k, t in sorted(self.tables.items())
            },
            "vacuum_levels_used_kpa": sorted({float(v) for v in self.played["vacuum_kpa"]}),
        }


def envelope_limits(settings: PlaySettings, rig: RigSpec) -> dict[str, tuple[float, float]]:
    """The finger's envelope on this rig; InputError if the fixed stroke geometry leaves it."""
    env = rig.envelope_for(settings.finger)
    fixed = {
        "distance_m": settings.distance_m,
        "depth_m": settings.depth_m,
        "acceleration_mps2": settings.acceleration_mps2,
        "up_velocity_mps": settings.up_velocity_mps,
    }
    for name, value in fixed.items():
        if name in env and not env[name].contains(value):
            raise InputError(
                f"{name} = {value:g} is outside the {settings.finger} finger's envelope "
                f"[{env[name].low:g}, {env[name].high:g}]", f"play settings: {name}",
            )
    return {name: (lim.low, lim.high) for name, lim in env.items()}


def stroke_tables(predictor: StrokePredictor, settings: PlaySettings, rig: RigSpec) -> dict[float, StrokeTable]:
    """One table per allowed vacuum level, down velocities capped by the envelope."""
    limits = envelope_limits(settings, rig)
    v_lo, v_hi = limits.get("vacuum_kpa", (-math.inf, math.inf))
    levels = [p for p in settings.vacuum_levels_kpa if v_lo - 1e-9 <= p <= v_hi + 1e-9]
    if not levels:
        raise InputError(
            f"no vacuum level of {list(settings.vacuum_levels_kpa)} lies in the envelope [{v_lo:g}, {v_hi:g}] kPa",
            "play settings: vacuum_levels_kpa",
        )
    cap = limits.get("down_velocity_mps", (0.0, 0.06))[1]
    tables = {float(p): StrokeTable.build(predictor, p, settings, cap) for p in levels}
    if not any(t.sounding.sum() >= 2 for t in tables.values()):
        raise InputError("the model predicts no sounding stroke inside the finger's envelope", "--model")
    return tables


def reachable_range(tables: dict[float, StrokeTable]) -> tuple[float, float]:
    """Quietest and loudest on-velocity over the vacuum levels, kept one step off silence."""
    ranges = [t.velocity_range for t in tables.values() if t.sounding.sum() >= 2]
    lo = min(r[0] for r in ranges)
    hi = max(r[1] for r in ranges)
    # The quietest stroke a model predicts sits at the edge of silence: aim a little above it.
    margin = min(1.0, 0.1 * (hi - lo))
    return lo + margin, hi


def phrases(notes: Sequence[Note], rest_s: float) -> list[int]:
    """Phrase number of each note: a new phrase after a rest of at least `rest_s`."""
    out, k = [], 0
    for i, n in enumerate(notes):
        if i and n.onset_s - notes[i - 1].offset_s >= rest_s:
            k += 1
        out.append(k)
    return out


def _level_for(targets: np.ndarray, tables: dict[float, StrokeTable]) -> float:
    """The vacuum whose reachable range needs the least clipping; ties go to faster strokes."""
    best: tuple[float, float, float] | None = None
    for level, table in tables.items():
        if table.sounding.sum() < 2:
            continue
        lo, hi = table.velocity_range
        clip = float(np.sum(np.maximum(lo - targets, 0) + np.maximum(targets - hi, 0)))
        speed = float(np.mean(table.inverse(targets)))
        key = (round(clip, 6), -speed, level)
        if best is None or key < best:
            best = key
    assert best is not None
    return best[2]


def plan_model(
    notes: Sequence[Note],
    predictor: StrokePredictor,
    settings: PlaySettings,
    rig: RigSpec,
    *,
    dynamics: DynamicsMode = "mapped",
    tables: dict[float, StrokeTable] | None = None,
) -> Plan:
    """Plan a melody with the model's inverse (see the module doc)."""
    if not notes:
        raise InputError("the song has no playable notes", "SONG")
    tables = tables if tables is not None else stroke_tables(predictor, settings, rig)
    dmap = DynamicsMap.fit([n.velocity for n in notes], reachable_range(tables), dynamics)
    targets = dmap.apply([n.velocity for n in notes])
    rest_s = VACUUM_BUDGET_FACTOR * rig.settle_s.after_vacuum_change_s
    phrase = np.asarray(phrases(notes, rest_s))
    level_of = {k: _level_for(targets[phrase == k], tables) for k in np.unique(phrase)}
    hold_cap = rig.envelope_for(settings.finger)["hold_s"].high
    rows = []
    for i, n in enumerate(notes):
        table = tables[level_of[int(phrase[i])]]
        speed = float(table.inverse(targets[i]))
        lo, hi = table.velocity_range
        reason = ""
        if not lo - 1e-6 <= targets[i] <= hi + 1e-6:
            reason = f"target {targets[i]:.1f} clipped to the reachable {lo:.1f}–{hi:.1f}"
        hold = min(float(table.arm_hold_for(speed, n.duration_s)), hold_cap)
        lead = float(table.lead(speed))
        rows.append(_row(i, n, targets[i], table, speed, hold, lead, reason))
    frame = schedule(pd.DataFrame(rows, columns=list(PLAN_COLUMNS)), tables, settings, rig)
    return Plan("model", frame, settings, dmap, dict(tables), _warnings(frame))


def _row(i: int, n: Note, target: float, table: StrokeTable, speed: float, hold: float,
         lead: float, reason: str) -> dict[str, Any]:
    s = table.settings
    return {
        "note_index": i, "pitch": n.pitch, "onset_s": n.onset_s, "offset_s": n.offset_s,
        "song_velocity": n.velocity, "target_velocity": float(target),
        "vacuum_kpa": table.vacuum_kpa, "down_velocity_mps": speed,
        "up_velocity_mps": s.up_velocity_mps, "acceleration_mps2": s.acceleration_mps2,
        "depth_m": s.depth_m, "distance_m": s.distance_m, "hold_s": hold,
        "predicted_velocity": float(table.predict_velocity(speed)),
        "predicted_lead_s": lead,
        "predicted_midi_hold_s": float(table.midi_hold(speed, hold)),
        "move_s": 0.0, "vacuum_change_s": 0.0, "start_s": n.onset_s - lead,
        "busy_s": table.busy_s(speed, hold), "late_s": 0.0, "status": "play", "reason": reason,
    }


def schedule(frame: pd.DataFrame, tables: dict[float, StrokeTable], settings: PlaySettings,
             rig: RigSpec, *, max_late_s: float | None = None, shorten: bool = True) -> pd.DataFrame:
    """Fit the presses one after another: shorten holds, allow small lateness, else skip.

    Each row's `start_s` is its ideal motion start (onset − lead); the arm is free again
    `busy_s` after a start; before the next press it moves sideways (`move_s`) and, for a new
    phrase level, waits for the vacuum (`vacuum_change_s`).
    """
    out = frame.copy()
    late_limit = settings.max_late_s if max_late_s is None else max_late_s
    vacuum_budget = VACUUM_BUDGET_FACTOR * rig.settle_s.after_vacuum_change_s
    prev: int | None = None
    for i in range(len(out)):
        row = out.iloc[i]
        if prev is None:
            prev = i
            continue
        p = out.iloc[prev]
        move = key_change_s(int(p.pitch), int(row.pitch), rig) if row.pitch != p.pitch else 0.0
        vac = vacuum_budget if abs(row.vacuum_kpa - p.vacuum_kpa) > 1e-9 else 0.0
        needed = float(p.start_s) + float(p.busy_s) + move + vac
        short = needed - float(row.start_s)
        if shorten and short > 0 and p.hold_s > 0:
            cut = min(short, float(p.hold_s))
            _set_hold(out, prev, float(p.hold_s) - cut, tables, settings)
            needed -= cut
            short -= cut
        _put(out, i, "move_s", move)
        _put(out, i, "vacuum_change_s", vac)
        if short > late_limit + 1e-9:
            _put(out, i, "status", "skip")
            _put(out, i, "reason", (
                f"no time to release and re-strike: the arm is free {short * 1e3:.0f} ms after "
                "this note's motion must start"
            ))
            continue
        if short > 0:
            _put(out, i, "start_s", needed)
            _put(out, i, "late_s", short)
            note = f"late by {short * 1e3:.0f} ms"
            old = str(out["reason"].iloc[i])
            _put(out, i, "reason", f"{old}; {note}" if old else note)
        prev = i
    return out


def _set_hold(frame: pd.DataFrame, i: int, hold_s: float, tables: dict[float, StrokeTable],
              settings: PlaySettings) -> None:
    """Shorten row i's arm hold and update what depends on it (MIDI hold, busy time)."""
    row = frame.iloc[i]
    _put(frame, i, "hold_s", hold_s)
    table = tables.get(float(row.vacuum_kpa))
    speed = float(row.down_velocity_mps)
    if table is not None:
        _put(frame, i, "predicted_midi_hold_s", float(table.midi_hold(speed, hold_s)))
        _put(frame, i, "busy_s", table.busy_s(speed, hold_s))
    else:
        _put(frame, i, "busy_s", busy_s(settings, speed, hold_s))


def _put(frame: pd.DataFrame, i: int, column: str, value: Any) -> None:
    """Set one cell of row position i."""
    frame.loc[frame.index[i], column] = value


def _warnings(frame: pd.DataFrame) -> tuple[str, ...]:
    out = []
    skipped = frame[frame["status"] == "skip"]
    if len(skipped):
        out.append(
            f"{len(skipped)} of {len(frame)} note(s) cannot be played in time and are skipped "
            f"(first: note {int(skipped.iloc[0].note_index)}: {skipped.iloc[0].reason})"
        )
    late = int((frame["late_s"] > 0).sum())
    if late:
        out.append(f"{late} note(s) start up to {frame['late_s'].max() * 1e3:.0f} ms late")
    clipped = int(frame["reason"].str.contains("clipped").sum())
    if clipped:
        out.append(f"{clipped} note(s) ask for a loudness outside the reachable range (clipped)")
    return tuple(out)
