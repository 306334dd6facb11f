"""Scoring a performance against its target: what a transcription metric and a listener hear.

Strict (as mir_eval scores transcriptions): a played note matches a target note of the same
pitch (pitches compared in Hz) whose onset is within 50 ms on the song clock of the tempo played
(a song played at 60 of its written 100 bpm is compared with itself at 60 bpm); offsets are
ignored. Timing, duration and loudness errors are measured on notes matched more loosely — same
pitch, onset within half the shortest inter-onset interval — so a consistently late player
still gets a (large) onset error instead of none. Velocity errors are against the mapped
targets (what the planner aimed at) and, separately, against the song's written velocities.

Tempo-relative (what a listener hears at the played tempo): the same matching with a tolerance
of a tenth of a beat (50 ms at 120 bpm), onset errors in beats, and the tempo and rhythm of the
performance itself — a straight line through (target onset, played onset) of the matched notes:
its slope is the tempo the listener hears, what is left around it the rhythm error.

Each target note gets a status: `matched` (within 50 ms), `late`/`early` (heard, outside 50
ms), `missed` (planned, not heard) or `skipped` (the plan dropped it).
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
BEAT_TOLERANCE = 0.1  # tempo-relative onset tolerance: a tenth of a beat (50 ms at 120 bpm)
FloatArray = npt.NDArray[np.float64]
STATUSES = ("matched", "late", "early", "missed", "skipped")
PER_NOTE_COLUMNS = ["pitch", "onset_s", "duration_s", "song_velocity", "target_velocity", "played_onset_s",
                    "played_duration_s", "played_velocity", "onset_error_s", "duration_error_s",
                    "velocity_error", "velocity_error_unmapped", "onset_error_beats", "status"]


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
    notes_paired: int  # paired by the loose timing match (same pitch, within half the shortest gap)
    per_note: pd.DataFrame  # one row per target note: matched played note, errors, status
    tempo_bpm: float = math.nan  # the tempo the target was played at
    f1_beat: float = math.nan  # tempo-relative F1 (a tenth of a beat)
    onset_rms_beats: float = math.nan
    heard_tempo_bpm: float = math.nan  # from the line through the matched onsets
    rhythm_rms_ms: float = math.nan  # onset error left around that line

    def to_dict(self) -> dict[str, Any]:
        counts = self.per_note["status"].value_counts() if len(self.per_note) else pd.Series(dtype=int)
        return {
            "f1": self.f1, "precision": self.precision, "recall": self.recall,
            "onset_rms_ms": self.onset_rms_ms, "onset_mean_ms": self.onset_mean_ms,
            "duration_mae_ms": self.duration_mae_ms, "velocity_mae": self.velocity_mae,
            "velocity_mae_unmapped": self.velocity_mae_unmapped,
            "notes_target": self.notes_target, "notes_played": self.notes_played,
            "notes_paired": self.notes_paired,
            "tempo_relative": {
                "tempo_bpm": _finite(self.tempo_bpm), "f1_beat": _finite(self.f1_beat),
                "beat_tolerance": BEAT_TOLERANCE, "onset_rms_beats": _finite(self.onset_rms_beats),
                "heard_tempo_bpm": _finite(self.heard_tempo_bpm), "rhythm_rms_ms": _finite(self.rhythm_rms_ms),
            },
            "note_status": {s: int(counts.get(s, 0)) for s in STATUSES},
        }

    def velocity_mae_between(self, start: int, stop: int) -> float:
        """Velocity MAE over target notes [start, stop) (matched ones only)."""
        part = self.per_note.iloc[start:stop]["velocity_error"].abs()
        return float(part.mean()) if part.notna().any() else math.nan

    def per_note_records(self) -> list[dict[str, Any]]:
        """The per-note table as JSON-able records (NaN → None)."""
        frame = self.per_note.astype(object).where(self.per_note.notna(), None)
        return [{str(k): v for k, v in row.items()} for row in frame.to_dict(orient="records")]


def _arrays(notes: Sequence[Note], shift_s: float) -> tuple[FloatArray, FloatArray]:
    import mir_eval

    intervals = np.array([[n.onset_s + shift_s, max(n.offset_s, n.onset_s + 1e-3) + shift_s] for n in notes],
                         dtype=np.float64).reshape(-1, 2)
    pitches = mir_eval.util.midi_to_hz(np.array([n.pitch for n in notes], dtype=np.float64))
    return intervals, np.asarray(pitches, dtype=np.float64)


def score_performance(
    target: Sequence[Note], played: Sequence[Note], target_velocity: npt.ArrayLike, *,
    tempo_bpm: float = math.nan, skipped: Sequence[bool] | None = None,
) -> Score:
    """Score played notes against target notes (`target_velocity`: mapped target per note).

    `target` is on the played song clock; `tempo_bpm` is the tempo it was played at (for the
    tempo-relative metrics); `skipped` marks notes the plan dropped.
    """
    import mir_eval.transcription as tr

    # mir_eval wants non-negative times: a note played before the song's zero is shifted with all.
    shift = -min([0.0] + [n.onset_s for n in (*target, *played)])
    ref_i, ref_p = _arrays(target, shift)
    est_i, est_p = _arrays(played, shift)
    targets = np.asarray(target_velocity, dtype=np.float64)
    beat_s = 60.0 / tempo_bpm if math.isfinite(tempo_bpm) and tempo_bpm > 0 else math.nan
    f1_beat = math.nan
    if len(target) and len(played):
        p, r, f, _ = tr.precision_recall_f1_overlap(ref_i, ref_p, est_i, est_p,
                                                     onset_tolerance=ONSET_TOLERANCE_S, offset_ratio=None)
        if math.isfinite(beat_s):
            f1_beat = float(tr.precision_recall_f1_overlap(ref_i, ref_p, est_i, est_p,
                                                           onset_tolerance=BEAT_TOLERANCE * beat_s,
                                                           offset_ratio=None)[2])
        loose = max(ONSET_TOLERANCE_S, 0.5 * _min_ioi(target))
        pairs = tr.match_notes(ref_i, ref_p, est_i, est_p, onset_tolerance=loose, offset_ratio=None)
    else:
        p = r = f = 0.0
        f1_beat = 0.0 if math.isfinite(beat_s) else math.nan
        pairs = []
    match = dict(pairs)
    dropped = list(skipped) if skipped is not None else [False] * len(target)
    rows = []
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
    per_note = pd.DataFrame(rows, columns=PER_NOTE_COLUMNS[:8])
    per_note["onset_error_s"] = per_note["played_onset_s"] - per_note["onset_s"]
    per_note["duration_error_s"] = per_note["played_duration_s"] - per_note["duration_s"]
    per_note["velocity_error"] = per_note["played_velocity"] - per_note["target_velocity"]
    per_note["velocity_error_unmapped"] = per_note["played_velocity"] - per_note["song_velocity"]
    per_note["onset_error_beats"] = per_note["onset_error_s"] / beat_s
    per_note["status"] = _statuses(per_note["onset_error_s"].to_numpy(float), dropped)
    onset = per_note["onset_error_s"].dropna().to_numpy(float)
    heard, rhythm = _tempo_line(per_note, tempo_bpm)

    def mean_abs(column: str) -> float:
        values = per_note[column].dropna().to_numpy(float)
        return float(np.mean(np.abs(values))) if values.size else math.nan

    rms = float(np.sqrt(np.mean(onset**2))) if onset.size else math.nan
    return Score(
        f1=float(f), precision=float(p), recall=float(r),
        onset_rms_ms=rms * 1e3, onset_mean_ms=float(np.mean(onset) * 1e3) if onset.size else math.nan,
        duration_mae_ms=mean_abs("duration_error_s") * 1e3,
        velocity_mae=mean_abs("velocity_error"),
        velocity_mae_unmapped=mean_abs("velocity_error_unmapped"),
        notes_target=len(target), notes_played=len(played), notes_paired=int(onset.size),
        per_note=per_note, tempo_bpm=float(tempo_bpm), f1_beat=f1_beat,
        onset_rms_beats=rms / beat_s if onset.size else math.nan, heard_tempo_bpm=heard, rhythm_rms_ms=rhythm,
    )


def _statuses(onset_error_s: FloatArray, skipped: Sequence[bool]) -> list[str]:
    out = []
    for error, dropped in zip(onset_error_s, skipped, strict=True):
        if dropped:
            out.append("skipped")
        elif not math.isfinite(error):
            out.append("missed")
        elif error > ONSET_TOLERANCE_S:
            out.append("late")
        elif error < -ONSET_TOLERANCE_S:
            out.append("early")
        else:
            out.append("matched")
    return out


def _tempo_line(per_note: pd.DataFrame, tempo_bpm: float) -> tuple[float, float]:
    """(heard tempo bpm, rhythm RMS ms) from a line through (target onset, played onset)."""
    heard = per_note.dropna(subset=["played_onset_s"])
    if len(heard) < 3 or not math.isfinite(tempo_bpm):
        return math.nan, math.nan
    x, y = heard["onset_s"].to_numpy(float), heard["played_onset_s"].to_numpy(float)
    slope, offset = np.polyfit(x, y, 1)
    residual = y - (slope * x + offset)
    return float(tempo_bpm / slope), float(np.sqrt(np.mean(residual**2)) * 1e3)


def _min_ioi(notes: Sequence[Note]) -> float:
    onsets = np.sort(np.array([n.onset_s for n in notes], dtype=np.float64))
    gaps = np.diff(onsets)
    gaps = gaps[gaps > 1e-6]
    return float(gaps.min()) if gaps.size else 1.0


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None
