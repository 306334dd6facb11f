"""What a drive of the forward model predicts for a batch, and how finely it must integrate.

A `Prediction` holds the model's fingertip and key at the batch's frames (when the batch has
trajectories) and its MIDI outcome per keystroke (when the drive reads the piano): the
on-velocity before rounding (so fits see a smooth function of the parameters), note-on time,
hold, and the margin by which the key passed (> 0) or missed (< 0) the trigger depth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pianobot.physics.model import KeystrokeModel

FloatArray = npt.NDArray[np.float64]

#: Typical finger compression at which a stiffening finger's stiffness is judged for the step.
_TYPICAL_COMPRESSION_M = 5e-3


def _nan(n: int) -> FloatArray:
    return np.full(n, np.nan)


@dataclass(frozen=True)
class Prediction:
    """Model outputs for a batch (see the module docstring); NaN where not predicted."""

    x1_m: FloatArray  # (n, T) fingertip at the frames
    x2_m: FloatArray  # (n, T) key at the frames
    v2_mps: FloatArray  # (n, T) key speed (empty when not asked for)
    force_n: FloatArray  # (n, T) finger force on the key
    on_velocity: FloatArray  # (n,) before rounding; NaN where silent
    t_on_s: FloatArray  # (n,) note-on after motion start
    hold_s: FloatArray  # (n,) note-off minus note-on
    margin_m: FloatArray  # (n,) deepest key travel minus the trigger depth

    @classmethod
    def trajectories(cls, x1_m: FloatArray, x2_m: FloatArray, v2_mps: FloatArray | None = None,
                     force_n: FloatArray | None = None) -> Prediction:
        """Trajectories only (no MIDI read)."""
        n = x1_m.shape[0]
        empty = np.zeros((n, 0))
        return cls(x1_m, x2_m, empty if v2_mps is None else v2_mps, empty if force_n is None else force_n,
                   _nan(n), _nan(n), _nan(n), _nan(n))

    @property
    def sounded(self) -> npt.NDArray[np.bool_]:
        """Keystrokes the model sounds."""
        return np.asarray(np.isfinite(self.on_velocity), dtype=bool)


def fastest_rate_per_s(model: KeystrokeModel, vacuum_kpa: FloatArray) -> float:
    """The fastest rate (1/s) of the model at these vacuum levels: each mass's natural frequency
    on all its springs (the stiffest effect included) and each mass's damping over its mass.

    The explicit integrator is stable and accurate only well inside h·ω < 2 and h·c/m < 1, and a
    fit may try stiff, heavily damped or strongly stiffening parameters.
    """
    fx = model.effects
    k_bed = fx.value("keybed", "bed_stiffness_npm", 0.0)
    c_bed = fx.value("keybed", "bed_damping_nspm", 0.0)
    width = fx.value("letoff", "letoff_width_m", 1.0)
    k_let = fx.value("letoff", "letoff_force_n", 0.0) / max(width, 1e-6)
    beta = fx.value("finger_stiffening", "stiffening_per_m", 0.0)
    grow = 1.0
    if beta > 0:
        bd = beta * _TYPICAL_COMPRESSION_M
        grow = math.exp(min(bd, 30.0)) if fx.form("finger_stiffening") == "exponential" else 1.0 + 3.0 * bd * bd
    rate = 1.0
    for p in np.unique(vacuum_kpa):
        lp = model.msd.at(float(p))
        k1 = lp.k1_npm * grow
        rate = max(rate, math.sqrt((lp.k0_npm + k1) / lp.m1_kg), math.sqrt((k1 + lp.k2_npm + k_bed + k_let) / lp.m2_kg),
                   (lp.c0_nspm + lp.c1_nspm) / lp.m1_kg, (lp.c1_nspm + lp.c2_nspm + c_bed) / lp.m2_kg)
    return rate
