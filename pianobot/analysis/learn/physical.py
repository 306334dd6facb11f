"""`PhysicsPredictor`: the physical model as a `StrokePredictor` (simulate, read the key like the piano).

`PhysicsPredictor.published()`, the study's model with the published parameters, is what `play`
uses when no model file is given; `learn.files.load_predictor` opens a saved physics model
(`pianobot.model/1`) as one.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from pianobot.analysis.learn.predictors import OUTPUT_COLUMNS, FloatArray, complete_inputs
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.piano import PianoParams, key_events, on_velocity_from_speed
from pianobot.physics.simulate import simulate_presses
from pianobot.plan.trial import press_from


class PhysicsPredictor:
    """A `StrokePredictor` that simulates the physical model and reads the key out like the piano.

    `predict` simulates every row (batched, compiled integrator); the on-velocity is the
    piano's curve before rounding, so the loudness is a continuous function of the speed.
    """

    def __init__(self, model: KeystrokeModel) -> None:
        self.model = model

    @classmethod
    def published(cls) -> PhysicsPredictor:
        """The study's model with the published parameters (the default for `play`)."""
        return cls(KeystrokeModel.study())

    def predict(self, frame: pd.DataFrame) -> pd.DataFrame:
        """Simulate each row's press and read out on-velocity, lead and hold (p_silent is 0 or 1)."""
        full = complete_inputs(frame)
        out = pd.DataFrame(index=frame.index, columns=list(OUTPUT_COLUMNS), dtype=float)
        if full.empty:
            return out
        presses = [press_from(dict(zip(full.columns, row, strict=True))) for row in full.to_numpy(float)]
        vacuum = full["vacuum_kpa"].to_numpy(float)
        piano = self.model.readout_params()
        values = np.full((len(presses), 4), np.nan)
        # Keystrokes in one batch share the longest one's duration: simulate slow presses
        # separately from fast ones so a crawl does not make every stroke expensive.
        order = np.argsort(full["down_velocity_mps"].to_numpy(float))
        for chunk in np.array_split(order, max(1, int(np.ceil(order.size / 16)))):
            sim = simulate_presses([presses[i] for i in chunk], vacuum[chunk], self.model)
            for row, i in enumerate(chunk):
                values[i] = self._readout(sim.t_s, sim.x2_m[row], piano)
        out.loc[:, list(OUTPUT_COLUMNS)] = values
        return out

    @staticmethod
    def _readout(t_s: FloatArray, x2_m: FloatArray, piano: PianoParams) -> list[float]:
        """[on_velocity, p_silent, lead_s, midi_hold_s] of one simulated key trace."""
        events, speed = key_events(t_s, x2_m, piano)
        ons = [e for e in events if e.type == "note_on"]
        if not ons:
            return [np.nan, 1.0, np.nan, np.nan]
        offs = [e for e in events if e.type == "note_off" and e.t_s >= ons[0].t_s]
        return [
            on_velocity_from_speed(speed, piano, rounded=False),  # continuous: play inverts it
            0.0,
            ons[0].t_s,
            offs[0].t_s - ons[0].t_s if offs else np.nan,
        ]
