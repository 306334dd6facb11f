"""Sequences of keystrokes from a known truth in which context matters (imports nothing from pianobot).

Each sequence has its own hidden finger state (a stiffness factor drawn once per sequence, as
when a soft finger is re-stiffened between sequences), and a key that was released shortly
before the next press is still rising and takes some of the next stroke's energy. Loudness
follows a saturating curve of the effective speed (not the piano model pianobot simulates);
the note-on comes after the finger has travelled the hover plus a trigger depth. MIDI
velocities are whole numbers.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

NOTES = (60, 62, 64, 65, 67, 69, 71)


def make_trials(n_sequences: int, length: int, *, seed: int = 0, state_spread: float = 0.35,
                carry: float = 14.0, noise: float = 1.5) -> pd.DataFrame:
    """A trials table like a sequence-mode run (sequence_id, sequence_order, controls, outcome)."""
    rng = np.random.default_rng(seed)
    rows = []
    t_s = 0.0
    for s in range(n_sequences):
        stiffness = 1.0 + state_spread * rng.uniform(-1.0, 1.0)
        released_at = -np.inf
        for order in range(length):
            speed = rng.uniform(0.01, 0.06)
            hold = rng.uniform(0.0, 0.4)
            distance = rng.uniform(0.004, 0.02)
            pause = rng.uniform(0.05, 0.6)
            t_start = max(t_s + pause, 0.0)
            lead = (distance + 0.006) / speed
            rising = np.exp(-(t_start + lead - released_at) / 0.15)  # key still moving up
            velocity = 105.0 * (1.0 - np.exp(-speed * stiffness / 0.025)) - carry * rising
            velocity += rng.normal(0.0, noise)
            sounded = velocity >= 4.0
            midi_hold = hold + 0.08 + rng.normal(0.0, 0.005)
            rows.append({
                "run_id": "truth", "index": len(rows), "sequence_id": s, "sequence_order": order,
                "note": int(rng.choice(NOTES)), "status": "ok" if sounded else "silent",
                "down_velocity_mps": speed, "up_velocity_mps": speed, "hold_s": hold,
                "distance_m": distance, "depth_m": 0.025, "acceleration_mps2": 1.0, "vacuum_kpa": -40.0,
                "t_start_s": t_start,
                "on_velocity": float(np.clip(np.round(velocity), 1, 127)) if sounded else np.nan,
                "t_on_s": lead + rng.normal(0.0, 0.002) if sounded else np.nan,
                "midi_hold_s": midi_hold if sounded else np.nan,
            })
            released_at = t_start + lead + midi_hold
            t_s = t_start + 2.0 * lead + hold
    return pd.DataFrame(rows)
