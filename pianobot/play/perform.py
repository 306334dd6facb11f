"""Executing a play run on the rig: the warm-up, then the song note by note, on the rig's clock.

`Performer` owns the run (kind "play") and the open rig for both stages, so the warm-up and the
song share one run folder, one clock and one journal of MIDI:

- `warm_up(trials)`: the warm-up keystrokes back to back (vacuum per level, move to the key,
  press, a short pause so the note-off arrives), returned as trials rows for the fit;
- `play(plan)`: each planned note becomes one timed keystroke through the rig's public API. The
  loop waits on the rig clock (virtual for the sim) until a phrase's vacuum change is due
  (`Rig.set_vacuum`), moves to the key as soon as the arm is back up from the previous press
  (`Rig.move_to_key`; the released key keeps returning meanwhile) and has the press start at its
  planned time (`Rig.press_at`, no settle pause).

The MIDI the piano sends is collected by contiguous time windows (each keystroke's, and the gaps
between), so no event is lost or counted twice. Trials rows carry a `phase` column (warmup |
song) and, for the song, the target and the prediction beside the outcome.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pianobot.io.midifile import Note
from pianobot.physics.trajectory import press_duration_s
from pianobot.plan import Trial
from pianobot.plan.trial import press_from
from pianobot.play.adapt import OnlineAdapter, adapted_stroke
from pianobot.play.geometry import stroke_trial
from pianobot.play.song_plan import SongPlan
from pianobot.play.tempo import note_numbers
from pianobot.play.warmup import WARMUP_SETTLE_S
from pianobot.progress import NO_PROGRESS, Progress
from pianobot.rig import open_rig
from pianobot.rig.errors import ConnectionLost, RigError, SafetyStop, SafetyViolation
from pianobot.rig.protocols import MidiEvent
from pianobot.run import TrialData, read_keystroke
from pianobot.run.rows import failed_trial, midi_table, samples_table, trials_table
from pianobot.spec import RigSpec
from pianobot.store import RunWriter

BATCH_NOTES = 16
TAIL_S = 1.0  # listen this long after the last press for a late note-off
# Columns every play trials row carries beyond a sweep's (NaN where they do not apply).
PLAY_COLUMNS = ("phase", "note_index", "onset_target_s", "target_velocity", "predicted_velocity",
                "predicted_lead_s", "motion_late_s")


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


class PerformanceStopped(RuntimeError):
    """The rig stopped a performance outside the song's own recovery (a protective stop in the
    warm-up, a lost connection): the run is kept with status failed."""


class Performer:
    """One play run on one open rig (a context manager; see the module doc)."""

    def __init__(self, rig: RigSpec, *, data_dir: Path, name: str, song_key: str, meta: dict[str, Any],
                 plan: pd.DataFrame, seed: int | None = None, world: Any | None = None,
                 progress: Progress = NO_PROGRESS, on_warning: Callable[[str], None] | None = None) -> None:
        self.on_warning = on_warning
        self.rig_spec, self.data_dir, self.name, self.song_key = rig, Path(data_dir), name, song_key
        self.seed = int(rig.seed if seed is None else seed)
        self.meta, self.initial_plan, self.world, self.progress = meta, plan, world, progress
        self.events: list[MidiEvent] = []
        self.warnings: list[str] = []
        self.recoveries: list[float] = []
        self.batch: list[TrialData] = []
        self.collected_to_s = 0.0
        self.pitch: int | None = None
        self.vacuum_kpa: float | None = None
        self._stack = ExitStack()

    def __enter__(self) -> Performer:
        spec = self.rig_spec.model_dump(mode="json")
        self.writer = self._stack.enter_context(RunWriter.create(
            self.data_dir, name=self.name, kind="play", plan=self.initial_plan,
            meta={**self.meta, "seed": self.seed, "rig": {"spec": spec}}))
        try:
            self.device = self._stack.enter_context(open_rig(self.rig_spec, seed=self.seed, world=self.world))
        except BaseException as exc:
            self.writer.finish("failed", f"{type(exc).__name__}: {exc}")
            self._stack.close()
            raise
        self.clock = self.device.clock
        self.collected_to_s = self.started_s = self.clock.now()
        rig_warnings = list(self.device.warnings)
        self.writer.update_meta(rig={"spec": spec, "description": self.device.describe(),
                                     **({"warnings": rig_warnings} if rig_warnings else {})})
        for line in rig_warnings:  # before any motion: the user may want to stop here
            if self.on_warning is not None:
                self.on_warning(f"rig: {line}")
        self.warnings.extend(rig_warnings)
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: object) -> None:
        try:
            if exc is not None and self.writer.meta.get("status") == "running":
                reason = "interrupted (Ctrl-C)" if isinstance(exc, KeyboardInterrupt) else f"{type(exc).__name__}: {exc}"
                self.writer.finish("failed", reason)
        finally:
            self._stack.close()
        if isinstance(exc, RigError):  # the rig stopped the performance: say which run keeps what it did
            raise PerformanceStopped(f"{exc}; run {self.run_id} keeps what was played (status failed)") from exc

    def replan(self, plan: pd.DataFrame) -> None:
        """Replace plan.parquet (before the song starts): the warm-up as played and the song as it
        will be played, so the run's plan names every keystroke it holds."""
        self.writer.replace_plan(plan)  # written atomically and recorded, so `runs check` agrees

    @property
    def run_id(self) -> str:
        return self.writer.run_id

    @property
    def run_path(self) -> Path:
        return self.writer.path

    # -- the warm-up ------------------------------------------------------------------------

    def warm_up(self, trials: Sequence[Trial]) -> tuple[pd.DataFrame, float]:
        """Play the warm-up keystrokes back to back; their trials rows and the lab time (s)."""
        rows: list[dict[str, Any]] = []
        t0 = self.clock.now()
        with self.progress.task("warm-up", total=len(trials)) as task:
            for trial in trials:
                self._set_vacuum(trial.vacuum_kpa)
                self._move(trial.note, trial.distance_m)
                data = self._keystroke(trial, None, settle_s=WARMUP_SETTLE_S)
                data = dataclasses.replace(data, midi=tuple(self._collect_gap()) + data.midi)
                data = dataclasses.replace(data, row={**data.row, **_play_fields("warmup")})
                rows.append(data.row)
                self._add(data)
                velocity = data.row.get("on_velocity", math.nan)
                task.advance(note=f"{trial.down_velocity_mps * 1e3:.0f} mm/s → "
                                  f"{'silent' if not _finite(velocity) else f'velocity {velocity:.0f}'}")
        self._flush()
        lab_time = self.clock.now() - t0
        self.writer.update_meta(warmup_lab_time_s=lab_time)
        return pd.DataFrame(rows), lab_time

    # -- the song ---------------------------------------------------------------------------

    def play(self, plan: SongPlan, adapter: OnlineAdapter | None = None) -> Performance:
        """Play `plan` note by note (see the module doc); the run is finished afterwards."""
        frame = plan.notes.assign(trial_id=[trial_id_for(self.song_key, int(i)) for i in plan.notes["note_index"]])
        played = frame[frame["status"] == "play"]
        rows: list[dict[str, Any]] = []
        status, reason, origin = "completed", None, self.clock.now()
        if played.empty:
            reason = "no note of the plan can be played"
        else:
            first = played.iloc[0]
            self._set_vacuum(float(first.vacuum_kpa))
            self._move(int(first.pitch), float(first.distance_m))
            now = self.clock.now()
            # Song time zero on the rig clock: the first motion starts lead_in after the setup.
            origin = now + plan.settings.lead_in_s - min(0.0, float(played["start_s"].min()))
            loop = _SongLoop(self, plan, origin, adapter)
            records: list[Any] = list(played.itertuples(index=False))
            with self.progress.task("notes", total=len(records)) as task:
                for i, row in enumerate(records):
                    try:
                        rows.append(loop.note(row, records[i + 1] if i + 1 < len(records) else None))
                    except SafetyStop as exc:
                        status, reason = "stopped", f"safety stop at note {note_numbers([row.note_index])}: {exc}"
                        break
                    task.advance(note=f"note {note_numbers([row.note_index])} (pitch {int(row.pitch)})")
        self.clock.sleep(TAIL_S)
        tail = self._collect_gap()
        if self.batch:
            self.batch[-1] = dataclasses.replace(self.batch[-1], midi=self.batch[-1].midi + tuple(tail))
        self._flush()
        first_motion = origin + (float(played["start_s"].min()) if len(played) else 0.0)
        song_events = [e for e in self.events if e.t_s >= first_motion - 1e-9]
        notes = pair_notes(song_events, origin)
        recovery = float(pd.Series(self.recoveries).median()) if self.recoveries else math.nan
        history = [] if adapter is None else list(adapter.history)
        self.writer.update_meta(origin_s=origin, observed_recovery_s=recovery, rig_warnings=self.warnings,
                                adaptation=None if adapter is None else history,
                                lab_time_s=self.clock.now() - self.started_s)
        self.writer.finish(status, reason)
        return Performance(tuple(notes), pd.DataFrame(rows), self.run_id, self.run_path, status, reason,
                           origin, history, recovery, tuple(self.warnings))

    # -- shared by both stages --------------------------------------------------------------

    def _keystroke(self, stroke: Trial, start_s: float | None, settle_s: float = 0.0) -> TrialData:
        """One keystroke; a dropped link is re-opened and the stroke tried once more."""
        for attempt in (1, 2):
            t0 = self.clock.now()
            try:
                result = self.device.press_at(stroke, attempt, start_at_s=start_s, settle_s=settle_s)
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

    def _add(self, data: TrialData) -> None:
        if len(self.batch) >= BATCH_NOTES:
            self._flush()
        self.batch.append(data)

    def _sleep_until(self, t_s: float) -> None:
        self.clock.sleep(t_s - self.clock.now())

    def _set_vacuum(self, vacuum_kpa: float) -> None:
        if self.vacuum_kpa is None or abs(vacuum_kpa - self.vacuum_kpa) > 1e-9:
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


class _SongLoop:
    """The note loop of `Performer.play`: timing, keystrokes, adaptation."""

    def __init__(self, performer: Performer, plan: SongPlan, origin_s: float, adapter: OnlineAdapter | None) -> None:
        self.p, self.plan, self.origin_s, self.adapter = performer, plan, origin_s, adapter

    def note(self, row: Any, following: Any | None) -> dict[str, Any]:
        p = self.p
        speed, predicted, lead = float(row.down_velocity_mps), float(row.predicted_velocity), float(row.predicted_lead_s)
        hold = float(row.hold_s)
        move = float(row.move_s) if p.pitch is not None and int(row.pitch) != p.pitch else 0.0
        changes_vacuum = p.vacuum_kpa is None or abs(float(row.vacuum_kpa) - p.vacuum_kpa) > 1e-9
        if self.adapter is not None:
            earliest = p.clock.now() + move + (float(row.vacuum_change_s) if changes_vacuum else 0.0)
            speed, hold, predicted, lead = adapted_stroke(self.adapter, self.plan, row, earliest, self.origin_s,
                                                          following)
        start = self.origin_s + float(row.onset_s) - lead
        if changes_vacuum:
            p._sleep_until(start - move - float(row.vacuum_change_s))
            p._set_vacuum(float(row.vacuum_kpa))
        # Move as soon as the arm is free: the plan left room for the move before `start`.
        p._move(int(row.pitch), float(row.distance_m))
        gap = p._collect_gap()
        # A played note is a planned trial like any other (repeat 0), so the rig and store read it.
        geometry = self.plan.geometry
        press = geometry.press(speed, hold) if geometry is not None else press_from(
            {**row._asdict(), "down_velocity_mps": speed, "hold_s": hold, "approach_m": 0.0})
        stroke = stroke_trial(str(row.trial_id), int(row.note_index), int(row.pitch), float(row.vacuum_kpa), press)
        data = p._keystroke(stroke, start)
        data = dataclasses.replace(data, midi=tuple(gap) + data.midi)
        on_velocity = data.row.get("on_velocity", math.nan)
        played = float(on_velocity) if _finite(on_velocity) else None
        t_on = data.row.get("t_on_s", math.nan)
        observed_lead = float(t_on) if _finite(t_on) else None
        extra = _play_fields("song", note_index=int(row.note_index), onset_target_s=float(row.onset_s),
                             target_velocity=float(row.target_velocity), predicted_velocity=predicted,
                             predicted_lead_s=lead,
                             motion_late_s=max(0.0, float(data.row.get("t_start_s", start)) - start))
        data = dataclasses.replace(data, row={**data.row, **extra})
        p._add(data)
        if self.adapter is not None and data.status != "failed":
            table = self.plan.tables[float(row.vacuum_kpa)]
            self.adapter.observe(int(row.note_index), float(row.vacuum_kpa), speed,
                                 float(table.predict_velocity(speed)), float(table.lead(speed)), played,
                                 observed_lead, forecast_velocity=predicted, forecast_lead_s=lead)
        return data.row


def _play_fields(phase: str, **values: float) -> dict[str, Any]:
    out: dict[str, Any] = {name: np.nan for name in PLAY_COLUMNS}
    out["phase"] = phase
    out["note_index"] = -1
    out.update(values)
    return out


def _finite(value: Any) -> bool:
    return isinstance(value, float | int) and math.isfinite(float(value))


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
