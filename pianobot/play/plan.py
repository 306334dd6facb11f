"""The model-based planner: melody notes in, one press per note out, with timing and flags.

Per note the planner chooses, from the model's tabulated strokes (`StrokeTable`):

- loudness: the down velocity whose predicted on-velocity equals the note's target (the song's
  velocity mapped onto the reachable range, see `DynamicsMap`), at the phrase's vacuum level;
- duration: the arm hold whose predicted note-on → note-off time equals the note's length;
- timing: motion start = onset − predicted lead (motion start → note-on).

The arm is free again once it is back up (`busy_s`); the lateral move to the next key starts
then, while the released key is still returning, and a re-strike of the same key waits for the
predicted note-off (the key back above its re-trigger depth). When a note cannot start on time
the previous note's hold is shortened first, then the note is played with a faster (louder)
stroke, whose lead is shorter; a note still later than `max_late_s` is skipped and reported with
the reason, so the notes after it stay in time.

The stroke geometry (hover distance, acceleration; depth and up velocity fixed) is chosen per
song: every candidate in the settings is planned and the one playing the most notes, then the
fewest forced louder, then the least late, then with the widest loudness range wins.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from pianobot.analysis.learn.predictors import StrokePredictor
from pianobot.errors import InputError
from pianobot.io.midifile import Note
from pianobot.play.dynamics import DynamicsMap, DynamicsMode
from pianobot.play.schedule import LOUDER, PLAN_COLUMNS, VACUUM_BUDGET_FACTOR, note_row, schedule
from pianobot.play.settings import PlaySettings
from pianobot.play.strokes import StrokeGeometry, StrokeTable
from pianobot.spec import RigSpec


@dataclass(frozen=True)
class Plan:
    """A performance plan: one row per melody note (`PLAN_COLUMNS`), song time in seconds.

    `status` is "play" or "skip"; `reason` says why a note is skipped, late, louder or clipped.
    `start_s` is the planned motion start in song time (it may be negative: the first press
    starts before the song's time zero by its lead).
    """

    planner: str  # "model" | "naive"
    notes: pd.DataFrame
    settings: PlaySettings
    dynamics: DynamicsMap | None = None
    tables: dict[float, StrokeTable] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    geometry: StrokeGeometry | None = None

    @property
    def played(self) -> pd.DataFrame:
        return self.notes[self.notes["status"] == "play"]

    def summary(self) -> dict[str, Any]:
        """Counts, geometry and the mapping, for JSON output and run.json."""
        frame = self.notes
        return {
            "planner": self.planner,
            "notes": int(len(frame)),
            "planned": int((frame["status"] == "play").sum()),
            "skipped": int((frame["status"] == "skip").sum()),
            "late": int((frame["late_s"] > 0).sum()),
            "louder_to_keep_time": int(frame["reason"].str.contains(LOUDER).sum()),
            "geometry": None if self.geometry is None else self.geometry.to_dict(),
            "dynamics": None if self.dynamics is None else self.dynamics.to_dict(),
            "reachable_by_vacuum": {
                f"{k:g}": list(t.velocity_range) for k, t in sorted(self.tables.items())
            },
            "vacuum_levels_used_kpa": sorted({float(v) for v in self.played["vacuum_kpa"]}),
        }


def geometries(settings: PlaySettings, rig: RigSpec) -> list[StrokeGeometry]:
    """The candidate stroke geometries; InputError if a setting leaves the finger's envelope."""
    env = rig.envelope_for(settings.finger)

    def checked(name: str, value: float) -> float:
        if name in env and not env[name].contains(value):
            raise InputError(
                f"{name} = {value:g} is outside the {settings.finger} finger's envelope "
                f"[{env[name].low:g}, {env[name].high:g}]", f"play settings: {name}",
            )
        return float(value)

    def top(name: str, fallback: float) -> float:
        return float(env[name].high) if name in env else fallback

    depth = checked("depth_m", settings.depth_m)
    up = checked("up_velocity_mps", settings.up_velocity_mps or top("up_velocity_mps", 0.7))
    accelerations = settings.accelerations_mps2 or (top("acceleration_mps2", 2.0),)
    return [
        StrokeGeometry(checked("distance_m", d), depth, checked("acceleration_mps2", a), up)
        for a in accelerations for d in settings.distances_m
    ]


def fastest_geometry(settings: PlaySettings, rig: RigSpec) -> StrokeGeometry:
    """The candidate with the shortest press cycle: shortest hover, highest acceleration."""
    return min(geometries(settings, rig), key=lambda g: (g.distance_m, -g.acceleration_mps2))


def envelope_limits(settings: PlaySettings, rig: RigSpec) -> dict[str, tuple[float, float]]:
    """The finger's envelope on this rig as (low, high) per parameter (geometry checked too)."""
    geometries(settings, rig)
    return {name: (lim.low, lim.high) for name, lim in rig.envelope_for(settings.finger).items()}


def stroke_tables(predictor: StrokePredictor, settings: PlaySettings, rig: RigSpec,
                  geometry: StrokeGeometry | None = None) -> dict[float, StrokeTable]:
    """One table per allowed vacuum level for a geometry (default: the fastest)."""
    limits = envelope_limits(settings, rig)
    geometry = geometry or fastest_geometry(settings, rig)
    v_lo, v_hi = limits.get("vacuum_kpa", (-math.inf, math.inf))
    levels = [p for p in settings.vacuum_levels_kpa if v_lo - 1e-9 <= p <= v_hi + 1e-9]
    if not levels:
        raise InputError(
            f"no vacuum level of {list(settings.vacuum_levels_kpa)} lies in the envelope [{v_lo:g}, {v_hi:g}] kPa",
            "play settings: vacuum_levels_kpa",
        )
    cap = limits.get("down_velocity_mps", (0.0, 0.06))[1]
    return {float(p): StrokeTable.build(predictor, p, geometry, settings, cap) for p in levels}


def _sounds(tables: dict[float, StrokeTable]) -> bool:
    return any(t.sounding.sum() >= 2 for t in tables.values())


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
    """Plan a melody with the model's inverse (see the module doc).

    `tables` fixes the stroke configuration (one geometry); otherwise every candidate geometry
    of the settings is planned and the best kept.
    """
    if not notes:
        raise InputError("the song has no playable notes", "SONG")
    if tables is not None:
        candidates = [tables]
    else:
        candidates = [t for g in geometries(settings, rig) if _sounds(t := stroke_tables(predictor, settings, rig, g))]
    if not candidates or not all(_sounds(t) for t in candidates):
        raise InputError("the model predicts no sounding stroke inside the finger's envelope", "--model")
    plans = [_plan_with(notes, t, settings, rig, dynamics) for t in candidates]
    return min(plans, key=_cost)


def _cost(plan: Plan) -> tuple[float, ...]:
    """Skipped notes, then notes forced louder, then lateness, then a narrower loudness range."""
    frame = plan.notes
    lo, hi = plan.dynamics.target_range if plan.dynamics is not None else (0.0, 0.0)
    return (
        float((frame["status"] == "skip").sum()),
        float(frame["reason"].str.contains(LOUDER).sum()),
        round(float(frame["late_s"].sum()), 3),
        -round(hi - lo, 1),
        plan.geometry.distance_m if plan.geometry is not None else 0.0,
    )


def _plan_with(notes: Sequence[Note], tables: dict[float, StrokeTable], settings: PlaySettings,
               rig: RigSpec, dynamics: DynamicsMode) -> Plan:
    """The plan for one stroke geometry (its tables, one per vacuum level)."""
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
        rows.append(note_row(i, n, float(targets[i]), table, speed, hold_cap, reason))
    frame = schedule(pd.DataFrame(rows, columns=list(PLAN_COLUMNS)), tables, settings, rig, hold_cap_s=hold_cap)
    geometry = next(iter(tables.values())).geometry
    return Plan("model", frame, settings, dmap, dict(tables), _warnings(frame), geometry)


def _warnings(frame: pd.DataFrame) -> tuple[str, ...]:
    out = []
    skipped = frame[frame["status"] == "skip"]
    if len(skipped):
        out.append(
            f"{len(skipped)} of {len(frame)} note(s) cannot be played in time and are skipped "
            f"(first: note {int(skipped.iloc[0].note_index)}: {skipped.iloc[0].reason})"
        )
    louder = int(frame["reason"].str.contains(LOUDER).sum())
    if louder:
        out.append(f"{louder} note(s) are played {LOUDER} (a faster stroke sounds sooner)")
    late = int((frame["late_s"] > 0).sum())
    if late:
        out.append(f"{late} note(s) start up to {frame['late_s'].max() * 1e3:.0f} ms late")
    clipped = int(frame["reason"].str.contains("clipped").sum())
    if clipped:
        out.append(f"{clipped} note(s) ask for a loudness outside the reachable range (clipped)")
    return tuple(out)
