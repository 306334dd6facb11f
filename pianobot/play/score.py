"""Scoring a performance against its target with mir_eval's note matching.

Note precision/recall/F1 follow the transcription convention: a played note matches a target
note of the same pitch (pitches compared in Hz) whose onset is within 50 ms; offsets are
ignored. Timing, duration and loudness errors are measured on notes matched more loosely — same
pitch, onset within half the shortest inter-onset interval — so a consistently late player
still gets a (large) onset error instead of none. Velocity errors are against the mapped
targets (what the planner aimed at) and, separately, against the song's written velocities.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.io.midifile import Note

ONSET_TOLERANCE_S = 0.05
FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Score:
    """How close a performance came to its target."""

    f1: float
    precision: float
    recall: float
    onset_rms_ms: float
    onset_mean_ms: float
    duration_mae_ms: float
    velocity_mae: float  # played vs mapped target, MIDI units
    velocity_mae_unmapped: float  # played vs the song's written velocity
    notes_target: int
    notes_played: int
    notes_matched: int  # by the loose timing match
    per_note: pd.DataFrame  # one row per target note: matched played note and errors

    def to_dict(self) -> dict[str, Any]:
        return {
            "f1": self.f1, "precision": self.precision, "recall": self.recall,
            "onset_rms_ms": self.onset_rms_ms, "onset_mean_ms": self.onset_mean_ms,
            "duration_mae_ms": self.duration_mae_ms, "velocity_mae": self.velocity_mae,
            "velocity_mae_unmapped": self.velocity_mae_unmapped,
            "notes_target": self.notes_target, "notes_played": self.notes_played,
            "notes_matched": self.notes_matched,
        }

    def velocity_mae_between(self, start: int, stop: int) -> float:
        """Velocity MAE over target notes [start, stop) (matched ones only)."""
        part = self.per_note.iloc[start:stop]["velocity_error"].abs()
        return float(part.mean()) if part.notna().any() else math.nan


def _arrays(notes: Sequence[Note], shift_s: float) -> tuple[FloatArray, FloatArray]:
    import mir_eval

    intervals = np.array([[n.onset_s + shift_s, max(n.offset_s, n.onset_s + 1e-3) + shift_s] for n in notes],
                         dtype=np.float64).reshape(-1, 2)
    pitches = mir_eval.util.midi_to_hz(np.array([n.pitch for n in notes], dtype=np.float64))
    return intervals, np.asarray(pitches, dtype=np.float64)


def score_performance(
    target: Sequence[Note], played: Sequence[Note], target_velocity: npt.ArrayLike
) -> Score:
    """Score played notes against target notes (`target_velocity`: mapped target per note)."""
    import mir_eval.transcription as tr

    # mir_eval wants non-negative times; a note played before the song's zero is shifted with all.
    shift = -min([0.0] + [n.onset_s for n in (*target, *played)])
    ref_i, ref_p = _arrays(target, shift)
    est_i, est_p = _arrays(played, shift)
    targets = np.asarray(target_velocity, dtype=np.float64)
    if len(target) and len(played):
        p, r, f, _ = tr.precision_recall_f1_overlap(ref_i, ref_p, est_i, est_p,
                                                     onset_tolerance=ONSET_TOLERANCE_S, offset_ratio=None)
        loose = max(ONSET_TOLERANCE_S, 0.5 * _min_ioi(target))
        pairs = tr.match_notes(ref_i, ref_p, est_i, est_p, onset_tolerance=loose, offset_ratio=None)
    else:
        p = r = f = 0.0
        pairs = []
    rows = []
    match = dict(pairs)
    for i, n in enumerate(target):
        j = match.get(i)
        row: dict[str, Any] = {"pitch": n.pitch, "onset_s": n.onset_s, "duration_s": n.duration_s,
                               "song_velocity": n.velocity, "target_velocity": targets[i]}
        if j is None:
            row.update(played_onset_s=np.nan, played_duration_s=np.nan, played_velocity=np.nan)
        else:
            q = played[j]
            row.update(played_onset_s=q.onset_s, played_duration_s=q.duration_s, played_velocity=float(q.velocity))
        rows.append(row)
    per_note = pd.DataFrame(rows, columns=["pitch", "onset_s", "duration_s", "song_velocity", "target_velocity",
                                           "played_onset_s", "played_duration_s", "played_velocity"])
    per_note["onset_error_s"] = per_note["played_onset_s"] - per_note["onset_s"]
    per_note["duration_error_s"] = per_note["played_duration_s"] - per_note["duration_s"]
    per_note["velocity_error"] = per_note["played_velocity"] - per_note["target_velocity"]
    per_note["velocity_error_unmapped"] = per_note["played_velocity"] - per_note["song_velocity"]
    onset = per_note["onset_error_s"].dropna().to_numpy(float)

    def mean_abs(column: str) -> float:
        values = per_note[column].dropna().to_numpy(float)
        return float(np.mean(np.abs(values))) if values.size else math.nan

    return Score(
        f1=float(f), precision=float(p), recall=float(r),
        onset_rms_ms=float(np.sqrt(np.mean(onset**2)) * 1e3) if onset.size else math.nan,
        onset_mean_ms=float(np.mean(onset) * 1e3) if onset.size else math.nan,
        duration_mae_ms=mean_abs("duration_error_s") * 1e3,
        velocity_mae=mean_abs("velocity_error"),
        velocity_mae_unmapped=mean_abs("velocity_error_unmapped"),
        notes_target=len(target), notes_played=len(played), notes_matched=int(onset.size),
        per_note=per_note,
    )


def _min_ioi(notes: Sequence[Note]) -> float:
    onsets = np.sort(np.array([n.onset_s for n in notes], dtype=np.float64))
    gaps = np.diff(onsets)
    gaps = gaps[gaps > 1e-6]
    return float(gaps.min()) if gaps.size else 1.0
