"""The study's demo logic, as a baseline: velocity → arm speed linearly, no lead compensation.

The original demo commanded a down velocity of 0.001·v m/s for MIDI velocity v, started each
press at the note's onset (ignoring the time a press takes before the note sounds), held for
the note's length and used one fixed vacuum. It also stepped between keys by a hard-coded key
width; on the simulated rig lateral positions do not affect the sound, so only the timing of the
move is kept here. Speeds are clipped into the finger's envelope so the baseline stays safe, and
it gets the same fast stroke geometry (shortest hover, highest acceleration) as the model planner
has to choose from, so the comparison measures the model, not the geometry.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from pianobot.errors import InputError
from pianobot.io.midifile import Note
from pianobot.play.plan import Plan, envelope_limits, fastest_geometry
from pianobot.play.schedule import PLAN_COLUMNS, schedule
from pianobot.play.settings import PlaySettings
from pianobot.play.strokes import busy_s
from pianobot.spec import RigSpec

DEMO_MPS_PER_VELOCITY = 0.001  # the demo's speed per MIDI velocity unit


def plan_naive(notes: Sequence[Note], settings: PlaySettings, rig: RigSpec) -> Plan:
    """The demo's plan: speed 0.001·v m/s (clipped to the envelope), start at the onset."""
    if not notes:
        raise InputError("the song has no playable notes", "SONG")
    limits = envelope_limits(settings, rig)
    geometry = fastest_geometry(settings, rig)
    v_lo, v_hi = limits.get("down_velocity_mps", (0.0, 0.06))
    vacuum = float(settings.vacuum_levels_kpa[0])
    hold_cap = limits.get("hold_s", (0.0, 2.0))[1]
    rows = []
    for i, n in enumerate(notes):
        speed = float(np.clip(DEMO_MPS_PER_VELOCITY * n.velocity, max(v_lo, settings.min_down_velocity_mps), v_hi))
        hold = float(min(n.duration_s, hold_cap))
        rows.append({
            "note_index": i, "pitch": n.pitch, "onset_s": n.onset_s, "offset_s": n.offset_s,
            "song_velocity": n.velocity, "target_velocity": float(n.velocity),
            "vacuum_kpa": vacuum, "down_velocity_mps": speed,
            **geometry.to_dict(), "hold_s": hold,
            "predicted_velocity": np.nan, "predicted_lead_s": 0.0, "predicted_midi_hold_s": np.nan,
            "predicted_release_s": np.nan, "move_s": 0.0, "vacuum_change_s": 0.0, "start_s": n.onset_s,
            "busy_s": busy_s(geometry, settings, speed, hold), "late_s": 0.0, "status": "play", "reason": "",
        })
    frame = pd.DataFrame(rows, columns=list(PLAN_COLUMNS))
    # The demo simply waited for each press to finish: a note that cannot start at its onset
    # starts as soon as the arm is free, however late (no skipping, no shortening).
    frame = schedule(frame, {}, settings, rig, max_late_s=float("inf"), shorten=False)
    return Plan("naive", frame, settings, None, {}, (), geometry)
