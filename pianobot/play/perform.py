"""Executing a plan on the rig, note by note, on the rig's clock; the performance is a run.

Each planned note becomes one timed keystroke through the rig's public API: the loop waits on
the rig clock (virtual for the sim) until a phrase's vacuum change is due (`Rig.set_vacuum`),
moves to the key as soon as the arm is back up from the previous press (`Rig.move_to_key`; the
released key keeps returning meanwhile) and has the press start at its planned time
(`Rig.press_at`, no settle pause). The MIDI the piano sends is collected by contiguous time
windows (each keystroke's, and the gaps between), so no event is lost or counted twice. The run
(kind "play") holds the plan, one trials row per note (with the target and the prediction beside
the outcome), samples including the sim's truth trace, key features and MIDI, like a sweep.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pianobot.io.midifile import Note
from pianobot.physics.trajectory import press_duration_s
from pianobot.plan import Trial
from pianobot.play.adapt import Forecast, OnlineAdapter
from pianobot.play.plan import Plan
from pianobot.rig import open_rig
from pianobot.rig.errors import ConnectionLost, SafetyStop, SafetyViolation
from pianobot.rig.protocols import MidiEvent
from pianobot.run import TrialData, read_keystroke
from pianobot.run.readout import failed_trial, midi_table, samples_table, trials_table
from pianobot.spec import RigSpec
from pianobot.store import RunWriter

BATCH_NOTES = 16
FEASIBILITY_GRID = 200  # down velocities checked for an on-time start when adapting
TAIL_S = 1.0  # listen this long after the last press for a late note-off


@dataclass(frozen=True)
class Performance:
    """What was played: notes on the song's time axis, per-note records, the run."""

    notes: tuple[Note, ...]  # played notes from the MIDI (song time)
    strokes: pd.DataFrame  # one row per executed note: target, prediction, outcome
    run_id: str
    run_path: Path
    status: str  # completed | stopped | failed
    reason: str | None
    origin_s: float  # rig-clock time of the song's time zero
    adaptation: list[dict[str, Any]] = field(default_factory=list)
    recovery_s: float = math.nan  # median observed arm occupancy beyond the press itself
    rig_warnings: tuple[str, ...] = ()  # what the rig reported (e.g. a re-strike that had to wait)


def trial_id_for(song_key: str, note_index: int) -> str:
    """A stable id per (song, note): the same song and note give the same id."""
    return hashlib.sha256(f"{song_key}|{note_index}".encode()).hexdigest()[:16]


def perform(
    plan: Plan,
    rig: RigSpec,
    *,
    data_dir: Path,
    name: str,
    song_key: str,
    meta: dict[str, Any],
    seed: int | None = None,
    world: Any | None = None,
    adapter: OnlineAdapter | None = None,
) -> Performance:
    """Play `plan` on the rig `rig` and store it as a run of kind "play" (see module doc)."""
    frame = plan.notes.assign(trial_id=[trial_id_for(song_key, int(i)) for i in plan.notes["note_index"]])
    chosen_seed = int(rig.seed if seed is None else seed)
    with RunWriter.create(Path(data_dir), name=name, kind="play",
                          meta={**meta, "seed": chosen_seed, "rig": {"spec": rig.model_dump(mode="json")}},
                          plan=frame) as writer:
        try:
            with open_rig(rig, seed=chosen_seed, world=world) as device:
                writer.update_meta(rig={"spec": rig.model_dump(mode="json"), "description": device.describe()})
                loop = _Loop(plan, frame, rig, device, writer, adapter)
                status, reason = loop.run()
        except BaseException as exc:
            writer.finish("failed", f"{type(exc).__name__}: {exc}")
            raise
        strokes = pd.DataFrame(loop.rows)
        notes = pair_notes(loop.events, loop.origin_s)
        recovery = float(pd.Series(loop.recoveries).median()) if loop.recoveries else math.nan
        writer.update_meta(origin_s=loop.origin_s, observed_recovery_s=recovery, rig_warnings=loop.warnings,
                           adaptation=None if adapter is None else adapter.history)
        writer.finish(status, reason)
        return Performance(tuple(notes), strokes, writer.run_id, writer.path, status, reason,
                           loop.origin_s, [] if adapter is None else list(adapter.history), recovery,
                           tuple(loop.warnings))


class _Loop:
    """The note loop: timing, keystrokes, MIDI windows, adaptation, store batches."""

    def __init__(self, plan: Plan, frame: pd.DataFrame, rig: RigSpec, device: Any,
                 writer: RunWriter, adapter: OnlineAdapter | None) -> None:
        self.plan, self.frame, self.rig, self.device, self.writer = plan, frame, rig, device, writer
        self.adapter = adapter
        self.clock = device.clock
        self.events: list[MidiEvent] = []
        self.rows: list[dict[str, Any]] = []
        self.recoveries: list[float] = []
        self.warnings: list[str] = []
        self.batch: list[TrialData] = []
        self.origin_s = 0.0
        self.collected_to_s = 0.0
        self.pitch: int | None = None
        self.vacuum_kpa: float | None = None

    def run(self) -> tuple[str, str | None]:
        played = self.frame[self.frame["status"] == "play"]
        if played.empty:
            return "completed", "no note of the plan can be played"
        first = played.iloc[0]
        self._set_vacuum(float(first.vacuum_kpa))
        self._move(int(first.pitch), float(first.distance_m))
        now = self.clock.now()
        # Song time zero on the rig clock: the first motion starts lead_in after the setup.
        self.origin_s = now + self.plan.settings.lead_in_s - min(0.0, float(played["start_s"].min()))
        self.collected_to_s = now
        status, reason = "completed", None
        rows = [row for _, row in played.iterrows()]
        for i, row in enumerate(rows):
            try:
                self._note(row, rows[i + 1] if i + 1 < len(rows) else None)
            except SafetyStop as exc:
                status, reason = "stopped", f"safety stop at note {int(row.note_index)}: {exc}"
                break
        self.clock.sleep(TAIL_S)
        tail = self._collect_gap()
        if self.batch:  # never empty here: batches are flushed before a note is added
            self.batch[-1] = dataclasses.replace(self.batch[-1], midi=self.batch[-1].midi + tuple(tail))
        self._flush()
        return status, reason

    def _note(self, row: pd.Series, following: pd.Series | None) -> None:
        speed, predicted, lead = float(row.down_velocity_mps), float(row.predicted_velocity), float(row.predicted_lead_s)
        hold = float(row.hold_s)
        move = float(row.move_s) if self.pitch is not None and int(row.pitch) != self.pitch else 0.0
        changes_vacuum = self.vacuum_kpa is None or abs(float(row.vacuum_kpa) - self.vacuum_kpa) > 1e-9
        if self.adapter is not None:
            earliest = self.clock.now() + move + (float(row.vacuum_change_s) if changes_vacuum else 0.0)
            speed, hold, predicted, lead = self._adapted_stroke(row, earliest, following)
        start = self.origin_s + float(row.onset_s) - lead
        if changes_vacuum:
            self._sleep_until(start - move - float(row.vacuum_change_s))
            self._set_vacuum(float(row.vacuum_kpa))
        # Move as soon as the arm is free: the plan left room for the move before `start`.
        self._move(int(row.pitch), float(row.distance_m))
        gap = self._collect_gap()
        # A played note is a planned trial like any other (repeat 0), so the rig and store read it.
        stroke = Trial(str(row.trial_id), int(row.note_index), 0, int(row.pitch), float(row.vacuum_kpa),
                       speed, float(row.up_velocity_mps), float(row.acceleration_mps2), float(row.depth_m),
                       float(row.distance_m), hold, 0.0)
        data = self._keystroke(stroke, start)
        data = dataclasses.replace(data, midi=tuple(gap) + data.midi)
        on_velocity = data.row.get("on_velocity", math.nan)
        played = None if not (isinstance(on_velocity, float) and math.isfinite(on_velocity)) else on_velocity
        t_on = data.row.get("t_on_s", math.nan)
        observed_lead = float(t_on) if isinstance(t_on, float) and math.isfinite(t_on) else None
        extra = {
            "note_index": int(row.note_index),
            "onset_target_s": float(row.onset_s),
            "target_velocity": float(row.target_velocity),
            "predicted_velocity": predicted,
            "predicted_lead_s": lead,
            "motion_late_s": max(0.0, float(data.row.get("t_start_s", start)) - start),
        }
        data = dataclasses.replace(data, row={**data.row, **extra})
        self.rows.append(data.row)
        if len(self.batch) >= BATCH_NOTES:
            self._flush()
        self.batch.append(data)
        if self.adapter is not None and data.status != "failed":
            table = self.plan.tables[float(row.vacuum_kpa)]
            self.adapter.observe(int(row.note_index), float(row.vacuum_kpa), speed,
                                 float(table.predict_velocity(speed)), float(table.lead(speed)), played,
                                 observed_lead, forecast_velocity=predicted, forecast_lead_s=lead)

    def _adapted_stroke(self, row: pd.Series, earliest_s: float,
                        following: pd.Series | None) -> tuple[float, float, float, float]:
        """Down velocity, hold, expected on-velocity and lead of a note under the corrected model.

        The stroke is the one with the least expected loudness error among those that can still
        start by `earliest_s` (+ the allowed lateness). The hold is then cut, as the planner
        does (shorten the previous hold before playing a note louder): so the arm is free when
        the plan expects it, and early enough for the stroke the corrected model wants for the
        following note — a model that learned the piano is louder asks for slower strokes, whose
        longer lead needs an earlier start than planned.
        """
        assert self.adapter is not None
        table = self.plan.tables[float(row.vacuum_kpa)]
        forecast = self._forecast(row)
        onset = self.origin_s + float(row.onset_s)
        # As the planner does: lateness (up to max_late_s) only where no stroke starts on time.
        on_time = onset - forecast.lead_s >= earliest_s
        if not on_time.any():
            on_time = onset - forecast.lead_s >= earliest_s - self.plan.settings.max_late_s
        k = self.adapter.choose(forecast, float(row.target_velocity), on_time)
        speed, lead = float(forecast.speeds_mps[k]), float(forecast.lead_s[k])
        free_by = self.origin_s + float(row.start_s) + float(row.busy_s)
        if following is not None:
            ahead = self._forecast(following)
            j = self.adapter.choose(ahead, float(following.target_velocity))
            between = float(following.move_s) if int(following.pitch) != int(row.pitch) else 0.0
            if abs(float(following.vacuum_kpa) - float(row.vacuum_kpa)) > 1e-9:
                between += float(following.vacuum_change_s)
            free_by = min(free_by, self.origin_s + float(following.onset_s) - float(ahead.lead_s[j]) - between)
        room = free_by - (onset - lead) - table.busy_s(speed, 0.0)
        hold = float(min(float(row.hold_s), max(0.0, room)))
        return speed, hold, float(forecast.velocity[k]), lead

    def _forecast(self, row: pd.Series) -> Forecast:
        """The adapter's corrected model over a fine grid of down velocities at the row's vacuum."""
        assert self.adapter is not None
        table = self.plan.tables[float(row.vacuum_kpa)]
        grid = np.linspace(table.speeds_mps[0], table.speeds_mps[-1], FEASIBILITY_GRID)
        return self.adapter.forecast(float(row.vacuum_kpa), grid, table.predict_velocity(grid), table.lead(grid))

    def _keystroke(self, stroke: Trial, start_s: float) -> TrialData:
        """One timed keystroke; a dropped link is re-opened and the note tried once more."""
        for attempt in (1, 2):
            t0 = self.clock.now()
            try:
                result = self.device.press_at(stroke, attempt, start_at_s=start_s)
            except ConnectionLost as exc:
                if attempt == 2:
                    return failed_trial(stroke, attempt, f"connection lost: {exc}", t0)
                self.device.reconnect()
                self.pitch = None  # the arm may be anywhere: hover again
                self._move(stroke.note, stroke.distance_m)
                continue
            except SafetyViolation as exc:
                return failed_trial(stroke, attempt, f"refused: {exc}", t0)
            self.events.extend(result.midi)
            self.collected_to_s = max(self.collected_to_s, self.clock.now(), result.press.t_end_s)
            self.recoveries.append(result.press.t_end_s - result.press.t_start_s - press_duration_s(stroke.press()))
            self.warnings.extend(result.press.warnings)
            return read_keystroke(stroke, attempt, result)
        raise AssertionError("unreachable")

    def _collect_gap(self) -> list[MidiEvent]:
        """Events since the last window closed (late note-offs, anything unexpected)."""
        now = self.clock.now()
        gap = self.device.keyboard.events_between(self.collected_to_s, now) if now > self.collected_to_s else []
        self.collected_to_s = max(self.collected_to_s, now)
        self.events.extend(gap)
        return gap

    def _sleep_until(self, t_s: float) -> None:
        self.clock.sleep(t_s - self.clock.now())

    def _set_vacuum(self, vacuum_kpa: float) -> None:
        self.device.set_vacuum(vacuum_kpa)  # waits for the regulator and the particles
        self.vacuum_kpa = vacuum_kpa

    def _move(self, pitch: int, distance_m: float) -> None:
        if pitch != self.pitch:
            self.device.move_to_key(pitch, distance_m)
            self.pitch = pitch

    def _flush(self) -> None:
        if not self.batch:
            return
        batch, self.batch = self.batch, []
        self.writer.append(trials_table(batch), samples_table(batch), midi_table(batch))


def pair_notes(events: Sequence[MidiEvent], origin_s: float) -> list[Note]:
    """Played notes from MIDI events (re-strike rule as in `read_song`), on song time."""
    open_notes: dict[int, tuple[float, int]] = {}
    notes: list[Note] = []
    last_t = origin_s
    for e in sorted(events, key=lambda e: (e.t_s, e.type != "note_off")):
        t = e.t_s - origin_s
        last_t = max(last_t, e.t_s)
        if e.type == "note_on" and e.velocity > 0:
            if e.note in open_notes:
                on, vel = open_notes.pop(e.note)
                notes.append(Note(e.note, on, t, vel))
            open_notes[e.note] = (t, e.velocity)
        elif e.note in open_notes:
            on, vel = open_notes.pop(e.note)
            notes.append(Note(e.note, on, max(t, on + 1e-3), vel))
    for pitch, (on, vel) in open_notes.items():
        notes.append(Note(pitch, on, max(last_t - origin_s, on + 1e-3), vel))
    return sorted(notes, key=lambda n: (n.onset_s, n.pitch))
