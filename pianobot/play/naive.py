"""The study's demo logic, as a baseline: velocity → arm speed linearly, no lead compensation.

The original demo commanded a down velocity of 0.001·v m/s for MIDI velocity v, started each
press at the note's onset (ignoring the time a press takes before the note sounds), held for
the note's length and used one fixed vacuum. It also stepped between keys by a hard-coded key
width; on the simulated rig lateral positions do not affect the sound, so only the timing of the
move is kept here. Speeds are clipped into the finger's envelope so the baseline stays safe, and
it gets the same fast stroke geometry (shortest hover, highest acceleration) as the model planner
has to choose from, so the comparison measures the model, not the geometry. Without a model it
cannot know which tempo is feasible: `auto` plays the written tempo, a tempo asked for as asked.
The demo simply waited for each press to finish: a note that cannot start at its onset starts
as soon as the arm is free, however late (no skipping, no shortening).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import pandas as pd

from pianobot.errors import InputError
from pianobot.io.midifile import Note
from pianobot.plan import key_change_s
from pianobot.play.geometry import envelope_limits, fastest_geometry, vacuum_levels
from pianobot.play.settings import PlaySettings
from pianobot.play.song_plan import SONG_PLAN_COLUMNS, SongPlan
from pianobot.play.tempo import TempoRequest, written_only
from pianobot.spec import RigSpec

DEMO_MPS_PER_VELOCITY = 0.001  # the demo's speed per MIDI velocity unit


def plan_naive(notes: Sequence[Note], settings: PlaySettings, rig: RigSpec, *,
               tempo: TempoRequest | None = None, written_bpm: float = 120.0) -> SongPlan:
    """The demo's plan: speed 0.001·v m/s (clipped to the envelope), start at the onset."""
    if not notes:
        raise InputError("the song has no playable notes", "SONG")
    choice = written_only(tempo or TempoRequest(), written_bpm)
    scale = choice.scale
    limits = envelope_limits(settings, rig)
    # The demo pressed in one move from its hover: no fast approach.
    geometry = replace(fastest_geometry(settings, rig), approach_velocity_mps=0.0)
    v_lo, v_hi = limits.get("down_velocity_mps", (0.0, 0.06))
    vacuum = vacuum_levels(settings, rig)[0]
    hold_cap = limits.get("hold_s", (0.0, 2.0))[1]
    velocity = np.array([n.velocity for n in notes], dtype=np.float64)
    speed = np.clip(DEMO_MPS_PER_VELOCITY * velocity, max(v_lo, settings.min_down_velocity_mps), v_hi)
    onset = np.array([n.onset_s for n in notes]) * scale
    duration = np.array([n.duration_s for n in notes]) * scale
    hold = np.minimum(duration, hold_cap)
    busy = geometry.durations_s(speed, hold) + settings.recovery_s
    start, move = onset.copy(), np.zeros(len(notes))
    free = -np.inf
    for i in range(len(notes)):
        if i and notes[i].pitch != notes[i - 1].pitch:
            move[i] = key_change_s(notes[i - 1].pitch, notes[i].pitch, rig)
        start[i] = max(onset[i], free + move[i])
        free = start[i] + busy[i]
    nan = np.full(len(notes), np.nan)
    frame = pd.DataFrame({
        "note_index": np.arange(len(notes)), "pitch": [n.pitch for n in notes],
        "written_onset_s": onset / scale, "onset_s": onset, "offset_s": onset + duration,
        "song_velocity": velocity.astype(int), "target_velocity": velocity, "vacuum_kpa": vacuum,
        "down_velocity_mps": speed, **geometry.to_dict(), "approach_m": 0.0, "hold_s": hold,
        "predicted_velocity": nan, "predicted_lead_s": 0.0, "predicted_midi_hold_s": nan,
        "predicted_release_s": nan, "move_s": move, "vacuum_change_s": 0.0, "start_s": start,
        "busy_s": busy, "late_s": start - onset, "tempo_limit_bpm": nan, "status": "play",
        "reason": ["" if late <= 0 else f"late by {late * 1e3:.0f} ms" for late in start - onset],
        "context_velocity": 0.0, "context_lead_s": 0.0,
    }, columns=list(SONG_PLAN_COLUMNS))
    return SongPlan("naive", frame, settings, None, {}, (), geometry, choice)
