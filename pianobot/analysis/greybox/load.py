"""The one store loader: runs in, one `KeystrokeBatch` out (trajectories, command, MIDI).

Runs are concatenated with their trial ids prefixed by the run id. Key trajectories come from
motion capture (or the simulator's truth) when the runs have them (`trajectories.keystroke_batch`:
one frame grid, the arm trace on the output clock); otherwise the batch is MIDI only.

The commanded press and the MIDI outcome come from the trials table. What a run does not record
is never silently assumed: a speed or depth is derived from the measured arm where an importer
estimated it (and said so in `notes`); an acceleration that was not recorded stays NaN, and the
commanded drive fits it (`forward.Commanded`); the distance defaults to 0 (the finger starts on
the key, as in the study's mocap takes), or, where the tracked fingertip clearly travelled
before the key moved, to that travel; either is noted.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pianobot.analysis.greybox.features import approach_distance_m, unloaded_travel_m
from pianobot.analysis.greybox.keystrokes import FloatArray, KeystrokeBatch
from pianobot.analysis.greybox.trajectories import OUTPUT_SOURCES, keystroke_batch
from pianobot.errors import InputError
from pianobot.spec.parameters import PRESS_PARAMETERS, recorded_or_followed
from pianobot.store import RunPaths, load_run


@dataclass(frozen=True)
class Loaded:
    """A loaded batch with the runs' trials (prefixed ids), data hashes and stated assumptions."""

    batch: KeystrokeBatch
    trials: pd.DataFrame
    hashes: dict[str, str]
    notes: tuple[str, ...]


def _file_hash(path: Path) -> str:
    digest = hashlib.sha256()
    for file in RunPaths(path).measurement_files():
        digest.update(file.read_bytes())
    return digest.hexdigest()


def _column(frame: pd.DataFrame, name: str) -> np.ndarray:
    if name not in frame:
        return np.full(len(frame), np.nan)
    return pd.to_numeric(frame[name], errors="coerce").to_numpy(dtype=np.float64)


def _has_trajectories(samples: pd.DataFrame) -> bool:
    if samples is None or samples.empty or "x2_m" not in samples:
        return False
    return bool((samples["source"].isin(OUTPUT_SOURCES) & samples["x2_m"].notna()).any())


def _commands(rows: pd.DataFrame, distance: np.ndarray, notes: set[str]) -> dict[str, np.ndarray]:
    """The commanded press per trial (`distance`: recorded, or as `_measured_distance` found it);
    derived values (and what stays unknown) are noted."""
    down = _column(rows, "down_velocity_mps")
    estimate = _column(rows, "arm_speed_mps")  # an imported take's arm speed estimate
    use = ~(down > 0) & (estimate > 0)
    if use.any():
        down = np.where(use, estimate, down)
        notes.add("down speed taken from the measured arm speed")
    depth = _column(rows, "depth_m")
    travel = _column(rows, "arm_travel_m") - distance  # measured arm travel = distance + depth
    use = ~(depth > 0) & (travel > 0)
    if use.any():
        depth = np.where(use, travel, depth)
        notes.add("depth taken from the measured arm travel")
    up = recorded_or_followed("up_velocity_mps", {"up_velocity_mps": _column(rows, "up_velocity_mps"),
                                                  "down_velocity_mps": down})
    accel = _column(rows, "acceleration_mps2")
    accel = np.where(accel > 0, accel, np.nan)
    if np.isnan(accel).any():
        notes.add("acceleration not recorded")
    hold = _column(rows, "hold_s")
    # An imported take times its strokes: with equal down and up moves, the hold is what the
    # stroke lasts beyond twice the time to the bottom.
    start, bottom, end = (_column(rows, c) for c in ("t_start_s", "t_bottom_s", "t_end_s"))
    derived = np.maximum((end - start) - 2.0 * (bottom - start), 0.0)
    use = ~np.isfinite(hold) & np.isfinite(derived)
    if use.any():
        hold = np.where(use, derived, hold)
        notes.add("hold derived from the take's stroke timing (equal down and up moves)")
    return {"down_velocity_mps": down, "up_velocity_mps": up, "acceleration_mps2": accel,
            "depth_m": depth, "hold_s": np.where(np.isfinite(hold), hold, 0.0)}


def _midi(rows: pd.DataFrame, recorded: bool) -> dict[str, np.ndarray]:
    """MIDI outcome per trial (all NaN when the runs recorded no MIDI)."""
    n = len(rows)
    if not recorded:
        return {k: np.full(n, np.nan) for k in ("on_velocity", "t_on_s", "hold_midi_s", "sounded")}
    velocity = _column(rows, "on_velocity")
    status = rows["status"].astype(str).to_numpy() if "status" in rows else np.full(n, "ok")
    sounded = (status == "ok") & np.isfinite(velocity)
    hold = _column(rows, "midi_hold_s")
    hold = np.where(np.isfinite(hold), hold, _column(rows, "t_off_s") - _column(rows, "t_on_s"))
    return {"on_velocity": np.where(sounded, velocity, np.nan), "t_on_s": np.where(sounded, _column(rows, "t_on_s"), np.nan),
            "hold_midi_s": np.where(sounded, hold, np.nan), "sounded": sounded.astype(np.float64)}


def load_keystrokes(run_ids: Sequence[str], data_dir: Path, *, x0_source: str = "auto",
                    vacuum_kpa: float | None = None, need_motion: bool = False,
                    schedule: pd.DataFrame | None = None, assumed_vacuum_kpa: float | None = None) -> Loaded:
    """Load runs as one batch (see the module docstring).

    Args:
        x0_source: the arm trace that drives the model: "arm", "mocap", "sim-truth" or "auto".
        vacuum_kpa: the vacuum of runs that do not record one (an imported Motive take).
        assumed_vacuum_kpa: without `vacuum_kpa`, the vacuum assumed (and noted) for a run that
            records none, instead of refusing it: for callers whose result does not hang on the
            level (discovery fits the finger's stiffness; it starts from the level's value).
        need_motion: raise when the runs hold no key trajectories (trajectory identification).
        schedule: the commanded presses (`read_schedule`) of runs that do not record them (an
            imported Motive take): matched to keystrokes by motion start.

    Raises:
        InputError: no run id, an unknown run, no trials, no vacuum, or (with `need_motion`) no
            key trajectories.
    """
    if not run_ids:
        raise InputError("give at least one run id", "RUN_ID")
    samples, trials, hashes, midi_recorded = [], [], {}, False
    assumed: list[str] = []
    imported_arm: set[str] = set()  # runs whose arm log came with an imported take
    for run_id in run_ids:
        run = load_run(run_id, data_dir)
        if run.run_id in hashes:  # the same run twice (or two prefixes of it): its keystrokes once
            continue
        t, s = run.trials, run.samples
        if t.empty:
            raise InputError("the run has no trials", run.run_id)
        fill = vacuum_kpa
        if fill is None and ("vacuum_kpa" not in t or t["vacuum_kpa"].isna().all()) and assumed_vacuum_kpa is not None:
            fill = assumed_vacuum_kpa
            assumed.append(run.run_id)
        if fill is not None:
            t = t.assign(vacuum_kpa=fill if "vacuum_kpa" not in t else t["vacuum_kpa"].fillna(fill))
        if "vacuum_kpa" not in t or t["vacuum_kpa"].isna().all():
            raise InputError("the run records no vacuum level; give --vacuum-kpa", run.run_id)
        midi_recorded |= bool(not run.midi.empty or ("on_velocity" in t and t["on_velocity"].notna().any()))
        prefix = f"{run.run_id}/"
        if "arm_log" in run.meta:
            imported_arm.add(prefix)
        trials.append(t.assign(trial_id=prefix + t["trial_id"].astype(str)))
        if s is not None and not s.empty:
            samples.append(s.assign(trial_id=prefix + s["trial_id"].astype(str)))
        hashes[run.run_id] = _file_hash(run.path)
    all_trials = pd.concat(trials, ignore_index=True)
    if "status" in all_trials:
        all_trials = all_trials[all_trials["status"] != "failed"]
    all_trials = all_trials.drop_duplicates("trial_id", keep="last")
    all_trials = all_trials[all_trials["vacuum_kpa"].notna()]
    frame = pd.concat(samples, ignore_index=True) if samples else pd.DataFrame()
    if _has_trajectories(frame):
        batch = keystroke_batch(frame, all_trials, x0_source=x0_source)
    elif need_motion:
        raise InputError("the run has no key trajectories (no key marker in its mocap, no simulated truth): trajectory "
                         "identification compares the model with the key's measured motion", "identify")
    else:
        n = len(all_trials)
        batch = KeystrokeBatch(tuple(all_trials["trial_id"].astype(str)), _column(all_trials, "vacuum_kpa"),
                               np.zeros(0), np.zeros((n, 0)), np.zeros((n, 0)), np.zeros((n, 0)),
                               distance_m=np.nan_to_num(_column(all_trials, "distance_m")))
        if not midi_recorded:
            silent = "n_note_on" in all_trials and bool((all_trials["n_note_on"] == 0).all())
            raise InputError(f"every one of the {n} keystrokes stayed silent and no key was tracked: no on-velocity, "
                             "hold or trajectory to compare with the model" if silent else
                             "the runs have neither key trajectories nor MIDI outcomes", ",".join(run_ids))
    rows = all_trials.set_index("trial_id").loc[list(batch.trial_id)]
    notes: set[str] = set()
    if batch.has_motion:  # a run with MIDI only beside a take: its keystrokes have nothing to fit here
        for run_id in hashes:
            mine = all_trials["trial_id"].str.startswith(f"{run_id}/")
            if mine.any() and not any(t.startswith(f"{run_id}/") for t in batch.trial_id):
                notes.add(f"run {run_id} has no key trajectories: its {int(mine.sum())} keystrokes are left out "
                          "(a trajectory fit compares the model with the key's measured motion)")
    if assumed:
        notes.add(f"vacuum not recorded ({', '.join(assumed)}): {assumed_vacuum_kpa:g} kPa assumed; only the finger "
                  "stiffness's starting value depends on it (the fit finds the take's own): give --vacuum-kpa to state it")
    batch = _held_keys(batch, rows, notes)
    if "distance_m" not in rows or rows["distance_m"].isna().any():
        batch = _measured_distance(batch, rows, notes)
    columns: dict[str, Any] = {**_commands(rows, batch.distance_m, notes), **_midi(rows, midi_recorded)}
    # A run's own arm log starts at the commanded motion start; an imported take (and an arm log
    # imported with it, cut at the marker's motion starts) does not know it.
    own_arm = [batch.arm_source == "arm" and not any(t.startswith(p) for p in imported_arm) for t in batch.trial_id]
    columns["command_start_s"] = np.where(own_arm, 0.0, np.nan)
    columns["motion_start_s"] = _column(rows, "t_start_s")
    batch = replace(batch, **columns)
    if schedule is not None:
        batch = _held_keys(attach_schedule(batch, rows, schedule, notes), rows, set())
    return Loaded(batch, all_trials.reset_index(drop=True), hashes, tuple(sorted(notes)))


#: A take whose fingertips travel this far (median) before the key moves started above the key,
HOVER_M = 1e-3
#: ... if the arm also moved them this far (median) before the finger was loaded at all.
UNLOADED_M = 5e-4


#: A take's measured hovers are read as one hover, their median, when their spread (10th to 90th
#: percentile) is within this share of it. Each keystroke's travel reads long by the pad's
#: compression when the key starts to move, more at higher speed (0.2-0.7 mm over a 5 mm hover
#: on independent takes), and a skin that pulls the key before touch shifts it further (4.7-6.5
#: mm for 5 mm); the model compresses the pad itself, so those keystrokes were modelled with the
#: compression counted twice. Hovers that differ by more (a hover swept within a take) are kept
#: per keystroke.
ONE_HOVER_SPREAD = 0.5


def _median(values: np.ndarray) -> float:
    """Median of the finite values (0 when there are none)."""
    finite = values[np.isfinite(values)]
    return float(np.median(finite)) if finite.size else 0.0


#: A key resting this far below the highest rest level of its take is held down (by dry friction,
#: after the previous keystroke); less is read as marker noise and the arm's repeatability.
HELD_KEY_MIN_M = 2.0e-5


def _held_keys(batch: KeystrokeBatch, rows: pd.DataFrame, notes: set[str]) -> KeystrokeBatch:
    """Where each keystroke's key started below its rest position (`key_start_m`).

    A key with dry friction in its action may stay part-way down after a keystroke: its spring
    is loaded when the next one starts, and the fingertip starts that much farther above it.
    An imported take records the key's rest level below the arm marker's before and after each
    press (`key_rest_m`, `key_rest_after_m`: a drift of the whole capture volume cancels in
    them); less the commanded distance it is the same for every press of a take but for where
    the key was left. The highest level of each take (trial ids "run/trial") is the key at
    rest; levels within `HELD_KEY_MIN_M` of it count as at rest.

    A key is only read as held where the take shows it being left: the level's changes from
    one press to the next must happen during the presses, or between them only as a key creeping
    back towards rest (`_left_by_presses`). A level that wanders otherwise between presses is the
    arm's pose or a marker, and the keys are taken at rest."""
    if not batch.has_motion or "key_rest_m" not in rows:
        return batch
    level = _column(rows, "key_rest_m") - batch.distance_m
    after = (_column(rows, "key_rest_after_m") - batch.distance_m if "key_rest_after_m" in rows
             else np.full(batch.n, np.nan))
    start = _column(rows, "t_start_s")  # where each press started on its take's clock
    out = np.zeros(batch.n)
    runs = batch.run_ids
    for run in np.unique(runs):
        mine = (runs == run) & np.isfinite(level)
        if not mine.any():
            continue
        below = level[mine] - level[mine].min()
        if below.max() < HELD_KEY_MIN_M:
            continue
        order = np.argsort(start[mine])
        if not _left_by_presses(level[mine][order], after[mine][order]):
            notes.add(f"the key's rest level wanders by up to {1e3 * below.max():.2f} mm between presses, not "
                      "during them (the arm's pose or a marker): every key taken to start at rest")
            continue
        out[mine] = np.where(below >= HELD_KEY_MIN_M, below, 0.0)
    held = out > 0
    if held.any():
        notes.add(f"the key started held down in {int(held.sum())} of {batch.n} keystrokes (up to "
                  f"{1e3 * out.max():.2f} mm below its rest position, left there by the keystroke before): "
                  "each is simulated from where its key was")
    return replace(batch, key_start_m=out)


def _left_by_presses(before: FloatArray, after: FloatArray) -> bool:
    """Whether a take's key levels (in time order, below its highest level positive) change
    during its presses: each press's level after it against the next press's level before it,
    within a quarter of the RMS change from press to press (a key left down moves only while it
    is pressed); or, where they also change between presses, only as a key left down and
    creeping back towards rest does (`_relaxing`)."""
    change = np.diff(before)
    between = before[1:] - after[:-1]
    ok = np.isfinite(change) & np.isfinite(between)
    if ok.sum() < 2:
        return False
    if float(np.sqrt(np.mean(between[ok] ** 2))) < 0.25 * float(np.sqrt(np.mean(change[ok] ** 2))):
        return True
    return _relaxing(before, after, between[ok])


def _relaxing(before: FloatArray, after: FloatArray, between: FloatArray) -> bool:
    """A key whose friction lets it creep under its spring (a friction law without a true
    stick, or one that only slows the key): after each press it is left down, and before the
    next it has risen part of the way back, never farther down and never above the take's
    highest level. A marker or the arm's pose wanders both ways between presses (zzz40: the key
    "sinks" by 25-35 um between presses and ends 75 um above its highest level before one)."""
    rest = float(np.nanmin(before))
    left = after[np.isfinite(after)] - rest
    return (bool(left.size) and float(left.min()) > -HELD_KEY_MIN_M and float(between.max()) < HELD_KEY_MIN_M
            and float(np.median(-between)) >= HELD_KEY_MIN_M)


def _measured_distance(batch: KeystrokeBatch, rows: pd.DataFrame, notes: set[str]) -> KeystrokeBatch:
    """Where the distance was not recorded: 0 (the finger starts on the key, as in the study's
    takes), unless the tracked fingertips clearly travelled before the key moved; then that
    travel, measured per keystroke (`features.approach_distance_m`): their median for every
    keystroke where they agree on one hover (`ONE_HOVER_SPREAD`), else each its own. The note
    says which."""
    recorded = _column(rows, "distance_m")
    # A key left part-way down starts that much farther from the fingertip (not a hover).
    travel = approach_distance_m(batch) - batch.key_start_m if batch.has_motion else np.full(batch.n, np.nan)
    unknown = ~np.isfinite(recorded)
    typical = _median(travel[unknown])
    # A finger resting on a key held by friction or a preload travels before the key moves too,
    # but compressed from the start: it hovered only if the arm first moved it unloaded.
    if typical > HOVER_M and batch.arm_measured:
        unloaded = unloaded_travel_m(batch)[unknown]
        if np.isfinite(unloaded).any() and _median(unloaded) <= UNLOADED_M:
            # Said apart: the take alone cannot always tell this from a hover (a finger whose
            # arm was still accelerating when it touched is loaded early too), the presses can.
            notes.add(f"distance 0 assumed where not recorded: the fingertips travelled {1e3 * typical:.2f} mm "
                      "(median) before the key moved, but the arm loaded the finger from the start, so the "
                      "finger is read as resting on a key held still (friction, a preload); if it hovered, "
                      "give the lab's presses (--presses) for the commanded distance")
            return batch
    if not typical > HOVER_M:
        notes.add("distance 0 assumed where not recorded (the finger starts on the key)")
        return batch
    found = travel[unknown & np.isfinite(travel)]  # not empty: their median is a hover
    one = float(np.percentile(found, 90) - np.percentile(found, 10)) <= ONE_HOVER_SPREAD * typical
    measured = np.full(batch.n, typical) if one else np.where(np.isfinite(travel), travel, typical)
    how = "one hover for the take, their median" if one else "per keystroke, median"
    notes.add(f"distance not recorded: measured from the take as the fingertip's travel before the key moved "
              f"({how} {1e3 * typical:.2f} mm; it reads long by the pad's compression, which identify and discover "
              "correct: the lab's presses give the commanded one)")
    return replace(batch, distance_m=np.where(unknown, measured, batch.distance_m),
                   distance_read_m=np.where(unknown, measured, np.nan))


#: Columns of a commanded schedule (a lab script's log of what it told the arm).
SCHEDULE_COLUMNS: tuple[str, ...] = ("t_start_s", *PRESS_PARAMETERS)


def read_schedule(path: Path) -> pd.DataFrame:
    """A commanded schedule CSV: one row per press with `SCHEDULE_COLUMNS` (times on the clock of
    the take it belongs to).

    Raises:
        InputError: the file is missing, not a CSV, or lacks a column.
    """
    try:
        frame = pd.read_csv(path)
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        raise InputError(f"cannot read the schedule ({exc})", str(path)) from None
    missing = [c for c in SCHEDULE_COLUMNS if c not in frame]
    if missing:
        raise InputError(f"the schedule lacks column(s) {', '.join(missing)}; expected {', '.join(SCHEDULE_COLUMNS)}",
                         str(path))
    return frame


def attach_schedule(batch: KeystrokeBatch, rows: pd.DataFrame, schedule: pd.DataFrame,
                    notes: set[str] | None = None) -> KeystrokeBatch:
    """The batch with each keystroke's commanded press from a schedule: the command whose start
    is the latest at or before the keystroke's observed motion start (trials' `t_start_s`, on
    the schedule's clock), within 1 s; unmatched keystrokes keep what they had."""
    observed = _column(rows, "t_start_s")
    starts = schedule["t_start_s"].to_numpy(dtype=np.float64)
    order = np.argsort(starts)
    starts = starts[order]
    out = {name: getattr(batch, name).copy() for name in ("command_start_s", "distance_read_m", *SCHEDULE_COLUMNS[1:])}
    matched = 0
    for i, t in enumerate(observed):
        k = int(np.searchsorted(starts, t + 0.05, side="right")) - 1  # a command up to 50 ms late
        if not math.isfinite(t) or k < 0 or t - starts[k] > 1.0:
            continue
        row = schedule.iloc[order[k]]
        out["command_start_s"][i] = float(starts[k] - t)
        out["distance_read_m"][i] = np.nan  # the commanded distance replaces the one read from the take
        for name in SCHEDULE_COLUMNS[1:]:
            out[name][i] = float(row[name])
        matched += 1
    if notes is not None:
        notes.discard("acceleration not recorded")
        notes.discard("down speed taken from the measured arm speed")
        notes.discard("depth taken from the measured arm travel")
        if matched == batch.n:  # every distance and hold is the commanded one now
            notes.difference_update({note for note in notes if note.startswith("distance ")})
            notes.discard("hold derived from the take's stroke timing (equal down and up moves)")
        notes.add(f"commanded presses from the schedule ({matched} of {batch.n} keystrokes matched)")
    return replace(batch, **out)


def load_batch(run_ids: Sequence[str], data_dir: Path, *, x0_source: str = "auto",
               vacuum_kpa: float | None = None) -> tuple[KeystrokeBatch, dict[str, str]]:
    """The runs' trajectory batch and each run's data hash (InputError without trajectories)."""
    loaded = load_keystrokes(run_ids, data_dir, x0_source=x0_source, vacuum_kpa=vacuum_kpa, need_motion=True)
    return loaded.batch, loaded.hashes

