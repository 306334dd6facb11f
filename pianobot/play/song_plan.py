"""The song plan: melody notes in, one press per note out, at a tempo the finger keeps.

(`pianobot.plan` is another thing: the trials an experiment spec expands into.)

Per note the planner chooses, from the model's tabulated strokes (`StrokeTable`):

- loudness: the down velocity whose predicted on-velocity equals the note's target (the song's
  velocity mapped onto the reachable range, see `DynamicsMap`), at the phrase's vacuum level;
  a note short of time may sound up to `loudness_tolerance` louder (a faster stroke sounds
  sooner);
- duration: the arm hold whose predicted note-on → note-off time equals the note's length;
- timing: motion start = onset − predicted lead (motion start → note-on).

Before anything is scheduled it works out, from the same strokes and the travel times, the
fastest tempo at which every note can be struck in time and which notes limit it (`tempo`).
`--tempo auto` (the default) plays at that tempo, never above the written one; a tempo the user
asks for is played as asked, skipping and reporting what cannot keep up (`schedule`).

The stroke geometry (hover distance, acceleration; depth and up velocity fixed) is chosen per
song among the settings' candidates: the one allowing the fastest tempo (up to the one played),
then the widest loudness range, then the shortest hover.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from pianobot.analysis.learn.predictors import StrokePredictor
from pianobot.errors import InputError
from pianobot.io.midifile import Note
from pianobot.plan import key_change_s
from pianobot.play.context import SongContext
from pianobot.play.dynamics import DynamicsMap, DynamicsMode
from pianobot.play.geometry import StrokeGeometry, geometries
from pianobot.play.schedule import (
    FASTER,
    LATE,
    LOUDER,
    SKIPPED,
    NoteTimes,
    Scheduled,
    need_s,
    schedule,
)
from pianobot.play.settings import PlaySettings
from pianobot.play.strokes import StrokeTable, stroke_tables
from pianobot.play.tempo import (
    Feasibility,
    TempoChoice,
    TempoRequest,
    choose_tempo,
    note_numbers,
    tempo_limits,
)
from pianobot.spec import RigSpec

# A phrase may change the vacuum only across a rest this many times the rig's settle time:
# the regulator's real settling varies with the size of the step.
VACUUM_BUDGET_FACTOR = 1.25
LOUDER_TEXT = "louder than asked to keep time"
# Planning passes with a sequence model: a changed stroke changes the next note's context.
CONTEXT_PASSES = 2
# A target this close to a level's reachable range is not worth a warning (half a MIDI step).
CLIP_TOLERANCE = 0.5
# A capped hold that sounds this much shorter than its note is worth a warning.
HOLD_SHORT_S = 0.1

SONG_PLAN_COLUMNS: tuple[str, ...] = (
    "note_index", "pitch", "written_onset_s", "onset_s", "offset_s", "song_velocity", "target_velocity",
    "vacuum_kpa", "down_velocity_mps", "up_velocity_mps", "acceleration_mps2", "depth_m",
    "distance_m", "approach_m", "hold_s", "predicted_velocity", "predicted_lead_s", "predicted_midi_hold_s",
    "predicted_release_s", "move_s", "vacuum_change_s", "start_s", "busy_s", "late_s",
    "tempo_limit_bpm", "status", "reason", "context_velocity", "context_lead_s",
)


@dataclass(frozen=True)
class SongPlan:
    """A song plan: one row per melody note (`SONG_PLAN_COLUMNS`), times on the played song clock.

    `status` is "play" or "skip"; `reason` says why a note is skipped, late, louder or clipped.
    `start_s` is the planned motion start (it may be negative: the first press starts before the
    song's time zero by its lead). `onset_s` is at the played tempo, `written_onset_s` at the
    written one; `tempo_limit_bpm` is the fastest tempo at which the note can be struck in time
    after the one before it.
    """

    planner: str  # "model" | "naive"
    notes: pd.DataFrame
    settings: PlaySettings
    dynamics: DynamicsMap | None = None
    tables: dict[float, StrokeTable] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    geometry: StrokeGeometry | None = None
    tempo: TempoChoice | None = None
    context: str | None = None  # what a sequence model changed (None: planned per note)

    @property
    def played(self) -> pd.DataFrame:
        return self.notes[self.notes["status"] == "play"]

    def summary(self) -> dict[str, Any]:
        """Counts, tempo, geometry and the mapping, for JSON output and run.json."""
        frame = self.notes
        return {
            "planner": self.planner,
            "notes": int(len(frame)),
            "planned": int((frame["status"] == "play").sum()),
            "skipped": int((frame["status"] == "skip").sum()),
            "late": int((frame["late_s"] > 0).sum()),
            "louder_to_keep_time": int(frame["reason"].str.contains(LOUDER_TEXT).sum()),
            "tempo": None if self.tempo is None else self.tempo.to_dict(),
            "geometry": None if self.geometry is None else self.geometry.describe(),
            "dynamics": None if self.dynamics is None else self.dynamics.to_dict(),
            "reachable_by_vacuum": {
                f"{k:g}": list(t.velocity_range) for k, t in sorted(self.tables.items())
            },
            "vacuum_levels_used_kpa": sorted({float(v) for v in self.played["vacuum_kpa"]}),
            "context": self.context,
        }


def reachable_range(tables: dict[float, StrokeTable]) -> tuple[float, float]:
    """Quietest and loudest on-velocity over the vacuum levels, kept one step off silence."""
    ranges = [t.velocity_range for t in tables.values() if t.sounds]
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
        if not table.sounds:
            continue
        lo, hi = table.velocity_range
        clip = float(np.sum(np.maximum(lo - targets, 0) + np.maximum(targets - hi, 0)))
        speed = float(np.mean(table.inverse(targets)))
        key = (round(clip, 6), -speed, level)
        if best is None or key < best:
            best = key
    assert best is not None
    return best[2]


@dataclass(frozen=True)
class _Prepared:
    """One geometry's per-note choices that do not depend on the tempo, and its tempo limits."""

    tables: dict[float, StrokeTable]
    dynamics: DynamicsMap
    targets: np.ndarray
    times: NoteTimes  # at the written tempo
    gap_s: np.ndarray  # move + vacuum change before each note (from the previous note)
    feasibility: Feasibility

    @property
    def geometry(self) -> StrokeGeometry:
        return next(iter(self.tables.values())).geometry


class _Moves:
    """Lateral move times between keys on a rig, cached per pair (a song reuses few pairs)."""

    def __init__(self, rig: RigSpec) -> None:
        self.rig = rig
        self.cache: dict[tuple[int, int], float] = {}

    def __call__(self, a: int, b: int) -> float:
        key = (a, b)
        if key not in self.cache:
            self.cache[key] = key_change_s(a, b, self.rig)
        return self.cache[key]


def _prepare(notes: Sequence[Note], tables: dict[float, StrokeTable], settings: PlaySettings, rig: RigSpec,
             dynamics: DynamicsMode, written_bpm: float, moves: _Moves) -> _Prepared:
    velocities = np.array([n.velocity for n in notes], dtype=np.float64)
    dmap = DynamicsMap.fit(velocities, reachable_range(tables), dynamics)
    targets = dmap.apply(velocities)
    budget = VACUUM_BUDGET_FACTOR * rig.settle_s.after_vacuum_change_s
    phrase = np.asarray(phrases(notes, budget))
    level_of = {int(k): _level_for(targets[phrase == k], tables) for k in np.unique(phrase)}
    level = np.array([level_of[int(k)] for k in phrase], dtype=np.float64)
    aim, fast = np.full(len(notes), np.nan), np.full(len(notes), np.nan)
    for key, table in tables.items():
        rows = level == key
        if rows.any():
            aim[rows] = table.inverse(targets[rows])
            fast[rows] = np.maximum(table.fastest_within(targets[rows], settings.loudness_tolerance), aim[rows])
    pitch = np.array([n.pitch for n in notes], dtype=np.int64)
    onset = np.array([n.onset_s for n in notes], dtype=np.float64)
    times = NoteTimes(onset, np.zeros(len(notes)), pitch, level, aim, fast)
    gap = np.zeros(len(notes))
    if len(notes) > 1:
        gap[1:] = [0.0 if a == b else moves(int(a), int(b)) for a, b in zip(pitch[:-1], pitch[1:], strict=True)]
        gap[1:] += np.where(level[1:] != level[:-1], budget, 0.0)
    feasibility = tempo_limits(onset, need_s(times, tables, settings, gap), written_bpm)
    return _Prepared(tables, dmap, targets, times, gap, feasibility)


def plan_model(
    notes: Sequence[Note],
    predictor: StrokePredictor,
    settings: PlaySettings,
    rig: RigSpec,
    *,
    dynamics: DynamicsMode = "mapped",
    tables: dict[float, StrokeTable] | None = None,
    tempo: TempoRequest | None = None,
    written_bpm: float = 120.0,
    context: SongContext | None = None,
) -> SongPlan:
    """Plan a melody (on its written time axis at `written_bpm`) with the model's inverse.

    `tables` fixes the stroke configuration (one geometry, its vacuum levels); otherwise every
    candidate geometry of the settings is tabulated and the best kept (see the module doc).
    `context`: a sequence model that corrects each note for the notes before it (`context`).
    """
    if not notes:
        raise InputError("the song has no playable notes", "SONG")
    request = tempo or TempoRequest()
    if tables is not None:
        candidates = [tables]
    else:
        candidates = [stroke_tables(predictor, settings, rig, g) for g in geometries(settings, rig)]
    candidates = [{k: t for k, t in c.items() if t.sounds} for c in candidates]
    candidates = [c for c in candidates if c]
    if not candidates:
        raise InputError("the model predicts no sounding stroke inside the finger's envelope", "--model")
    moves = _Moves(rig)
    prepared = [_prepare(notes, c, settings, rig, dynamics, written_bpm, moves) for c in candidates]
    wanted = written_bpm if request.mode != "bpm" or request.bpm is None else request.bpm

    def rank(p: _Prepared) -> tuple[float, float, float]:
        lo, hi = p.dynamics.target_range
        return (-round(min(p.feasibility.fastest_bpm, wanted), 6), -round(hi - lo, 1), p.geometry.distance_m)

    best = min(prepared, key=rank)
    choice = choose_tempo(request, best.feasibility)
    scheduled = _scheduled(notes, best, choice, settings, rig, moves)
    frame = _frame(notes, best, choice, scheduled)
    if context is not None and context.used:
        frame = _in_context(notes, best, choice, settings, rig, moves, frame, context)
    hold_cap = rig.envelope_for(settings.finger)["hold_s"].high
    return SongPlan("model", frame, settings, best.dynamics, dict(best.tables), _warnings(frame, choice, hold_cap),
                    best.geometry, choice, None if context is None else context.describe())


def _in_context(notes: Sequence[Note], prepared: _Prepared, choice: TempoChoice, settings: PlaySettings,
                rig: RigSpec, moves: _Moves, frame: pd.DataFrame, context: SongContext) -> pd.DataFrame:
    """Re-aim every note at its target minus the context's loudness effect, re-schedule, then
    move each motion start by the context's lead effect as far as the arm's free time allows."""
    for _ in range(CONTEXT_PASSES):
        dv, _ = context.effects(frame)
        aimed = _aimed(prepared, prepared.targets - dv, settings)
        frame = _frame(notes, aimed, choice, _scheduled(notes, aimed, choice, settings, rig, moves))
    dv, dlead = context.effects(frame)
    return _shifted(frame, dv, dlead)


def _aimed(prepared: _Prepared, aim_targets: np.ndarray, settings: PlaySettings) -> _Prepared:
    """The same notes and targets, each stroke aimed at `aim_targets` instead."""
    times = prepared.times
    aim, fast = times.aim_mps.copy(), times.fast_mps.copy()
    for key, table in prepared.tables.items():
        rows = times.level == key
        if rows.any():
            aim[rows] = table.inverse(aim_targets[rows])
            fast[rows] = np.maximum(table.fastest_within(aim_targets[rows], settings.loudness_tolerance), aim[rows])
    return dataclasses.replace(prepared, times=dataclasses.replace(times, aim_mps=aim, fast_mps=fast))


def _shifted(frame: pd.DataFrame, dv: np.ndarray, dlead: np.ndarray) -> pd.DataFrame:
    """Context effects into the plan: predicted loudness, and the lead's change bounded so each
    motion starts after the previous note frees the arm and frees it in time for the next."""
    out = frame.copy()
    start, busy = out["start_s"].to_numpy(float).copy(), out["busy_s"].to_numpy(float)
    gap = (out["move_s"] + out["vacuum_change_s"]).to_numpy(float)
    played = np.flatnonzero((out["status"] == "play").to_numpy())
    applied = np.zeros(len(out))
    for j, i in enumerate(played):
        lo = start[played[j - 1]] + busy[played[j - 1]] + gap[i] if j else -np.inf
        hi = start[played[j + 1]] - busy[i] - gap[played[j + 1]] if j + 1 < len(played) else np.inf
        new = float(np.clip(start[i] - dlead[i], lo, max(lo, hi)))
        applied[i], start[i] = start[i] - new, new
    out["start_s"] = start
    out["predicted_lead_s"] = out["predicted_lead_s"] + applied
    out["predicted_release_s"] = out["predicted_release_s"] + applied
    out["predicted_velocity"] = np.clip(out["predicted_velocity"] + dv, 1.0, 127.0)
    out["context_velocity"], out["context_lead_s"] = dv, applied
    return out


def _scheduled(notes: Sequence[Note], prepared: _Prepared, choice: TempoChoice, settings: PlaySettings,
               rig: RigSpec, moves: _Moves) -> Scheduled:
    """Schedule the notes at the chosen tempo (times stretched by its scale)."""
    scale = choice.scale
    times = prepared.times
    hold_cap = rig.envelope_for(settings.finger)["hold_s"].high
    durations = np.array([n.duration_s for n in notes], dtype=np.float64) * scale
    wanted = np.zeros(len(notes))
    for key, table in prepared.tables.items():
        rows = times.level == key
        wanted[rows] = np.minimum(table.arm_hold_for(times.aim_mps[rows], durations[rows]), hold_cap)
    at_tempo = NoteTimes(times.onset_s * scale, wanted, times.pitch, times.level, times.aim_mps, times.fast_mps)
    budget = VACUUM_BUDGET_FACTOR * rig.settle_s.after_vacuum_change_s
    return schedule(at_tempo, prepared.tables, settings, moves, budget, allow_skip=True)


def _frame(notes: Sequence[Note], prepared: _Prepared, choice: TempoChoice, s: Scheduled) -> pd.DataFrame:
    """The plan table: the scheduler's choices with the model's predictions beside them."""
    n = len(notes)
    scale = choice.scale
    times = prepared.times
    skipped = (s.flags & SKIPPED) > 0
    speed = np.where(skipped, times.aim_mps, s.speed_mps)
    velocity, lead, hold0, slope, busy0 = (np.full(n, np.nan) for _ in range(5))
    for key, table in prepared.tables.items():
        rows = times.level == key
        v = speed[rows]
        velocity[rows], lead[rows] = table.predict_velocity(v), table.lead(v)
        hold0[rows], slope[rows], busy0[rows] = table.hold0(v), table.slope(v), table.busy0(v)
    onset = times.onset_s * scale
    midi_hold = hold0 + slope * s.hold_s
    g = prepared.geometry
    frame = pd.DataFrame({
        "note_index": np.arange(n), "pitch": times.pitch, "written_onset_s": times.onset_s,
        "onset_s": onset, "offset_s": onset + np.array([x.duration_s for x in notes]) * scale,
        "song_velocity": [x.velocity for x in notes], "target_velocity": prepared.targets,
        "vacuum_kpa": times.level, "down_velocity_mps": speed, "up_velocity_mps": g.up_velocity_mps,
        "acceleration_mps2": g.acceleration_mps2, "depth_m": g.depth_m, "distance_m": g.distance_m,
        "approach_m": g.approach_m(speed), "hold_s": s.hold_s, "predicted_velocity": velocity, "predicted_lead_s": lead,
        "predicted_midi_hold_s": midi_hold, "predicted_release_s": lead + midi_hold,
        "move_s": s.move_s, "vacuum_change_s": s.vacuum_change_s,
        "start_s": np.where(skipped, onset - lead, s.start_s), "busy_s": busy0 + s.hold_s,
        "late_s": s.late_s, "tempo_limit_bpm": prepared.feasibility.tempo_limit_bpm,
        "status": np.where(skipped, "skip", "play"), "reason": _reasons(prepared, s, velocity),
        "context_velocity": 0.0, "context_lead_s": 0.0,
    }, columns=list(SONG_PLAN_COLUMNS))
    return frame


def _reasons(prepared: _Prepared, s: Scheduled, velocity: np.ndarray) -> list[str]:
    """Why a note is clipped, faster, louder, late or skipped (empty when played as planned)."""
    out = []
    for i, (flag, target) in enumerate(zip(s.flags.tolist(), prepared.targets.tolist(), strict=True)):
        parts = []
        table = prepared.tables[float(prepared.times.level[i])]
        t_lo, t_hi = table.velocity_range
        if not t_lo - CLIP_TOLERANCE <= target <= t_hi + CLIP_TOLERANCE:
            parts.append(f"target {target:.1f} clipped to the reachable {t_lo:.1f}–{t_hi:.1f}")
        if flag & SKIPPED:
            parts.append("no time to release and re-strike: the arm is not free when this note's "
                         f"motion must start (its limit is {prepared.feasibility.tempo_limit_bpm[i]:.3g} bpm)")
        elif flag & LOUDER:
            parts.append(f"{LOUDER_TEXT} ({velocity[i]:.1f} for {target:.1f})")
        elif flag & FASTER:
            parts.append(f"a faster stroke within the loudness tolerance ({velocity[i]:.1f} for {target:.1f})")
        if flag & LATE and not flag & SKIPPED:
            parts.append(f"late by {s.late_s[i] * 1e3:.0f} ms")
        out.append("; ".join(parts))
    return out


def _warnings(frame: pd.DataFrame, choice: TempoChoice, hold_cap_s: float) -> tuple[str, ...]:
    out = []
    message = choice.message()
    if message:
        out.append(message)
    skipped = frame[frame["status"] == "skip"]
    if len(skipped):
        out.append(
            f"{len(skipped)} of {len(frame)} note(s) cannot be played in time and are skipped "
            f"(first: note {note_numbers([skipped.iloc[0].note_index])}: {skipped.iloc[0].reason})"
        )
    louder = int(frame["reason"].str.contains(LOUDER_TEXT).sum())
    if louder:
        out.append(f"{louder} note(s) are played {LOUDER_TEXT} (a faster stroke sounds sooner)")
    late = int((frame["late_s"] > 0).sum())
    if late:
        out.append(f"{late} note(s) start up to {frame['late_s'].max() * 1e3:.0f} ms late")
    clipped = int(frame["reason"].str.contains("clipped").sum())
    if clipped:
        out.append(f"{clipped} note(s) ask for a loudness outside the reachable range (clipped)")
    # A note longer than the finger may hold a key sounds shorter than written (the hold is capped
    # by the finger's safety envelope): said, as a shortened or dropped note is.
    played = frame[frame["status"] != "skip"]
    capped = played[(played["hold_s"] >= hold_cap_s * (1 - 1e-9))
                    & (played["predicted_midi_hold_s"] < (played["offset_s"] - played["onset_s"]) - HOLD_SHORT_S)]
    if len(capped):
        longest = float((capped["offset_s"] - capped["onset_s"]).max())
        out.append(f"{len(capped)} note(s) are held shorter than written (up to {longest:.1f} s written): the finger "
                   f"holds a key at most {hold_cap_s:g} s (its safety envelope's hold_s)")
    return tuple(out)
