"""The study's outcomes of the linear model (trigger speed and hold time), reproduced.

The original MATLAB scripts drove the state-space model (Simulink, fixed step dt = 1 ms) with a
constant-speed ramp: the arm goes down `depth` at `vel` (no acceleration phase), holds, and comes
back up at the same speed; the simulation stops when the arm is back, at 2·depth/vel + hold.
The finger rests on the key at the start (no approach distance). From the key trace they read:

- "MIDI velocity": the key speed at the sample nearest the trigger depth, by forward difference
  (x2[i+1] − x2[i]) / dt;
- hold time: the number of samples with the key beyond the trigger depth, times dt.

The scripts took the nearest sample over the first half of the record. Here the crossing is the
first sample pair that straddles the trigger depth on the way down, and of those two the nearer
one is used: the same sample whenever the key descends monotonically to the trigger (always so
for these parameters), and still the descent when a slow key only triggers late.

The scripts also used other numbers than the published ones (k2 halved to 150.6 N/m);
`STUDY_SCRIPT_PARAMS` holds them, and `study_outcomes` uses them unless told otherwise.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.physics.linear import StateSpace, lsim_uniform, state_space
from pianobot.physics.msd import MSDParams
from pianobot.physics.trajectory import Press, sample_presses

FloatArray = npt.NDArray[np.float64]

STUDY_SCRIPT_PARAMS = MSDParams(k2_npm=150.6)  # forward_control.m: k2 = 0.3012 N/mm × 0.5
STUDY_DT_S = 1e-3

STUDY_OUTCOME_COLUMNS = ("vacuum_kpa", "velocity_mps", "on_speed_mps", "hold_s")


def study_arm_input(
    depth_m: float, velocity_mps: float, hold_s: float, dt_s: float = STUDY_DT_S
) -> tuple[FloatArray, FloatArray]:
    """The study's arm input: ramp down `depth_m` at `velocity_mps`, hold, ramp back up.

    Returns (t_s, x0_m) sampled every `dt_s` from 0 to the end of the upward ramp.
    """
    if not (depth_m > 0.0 and velocity_mps > 0.0 and hold_s >= 0.0 and dt_s > 0.0):
        raise ValueError(
            "study input needs depth > 0 m, velocity > 0 m/s, hold >= 0 s, dt > 0 s; got "
            f"depth={depth_m}, velocity={velocity_mps}, hold={hold_s}, dt={dt_s}."
        )
    t_stop_s = 2.0 * depth_m / velocity_mps + hold_s
    n = int(math.floor(t_stop_s / dt_s + 1e-9)) + 1
    t = np.arange(n, dtype=np.float64) * dt_s
    # The study's arm: on the key at the start, the same speed both ways, a ramp (no acceleration).
    press = Press(distance_m=0.0, depth_m=depth_m, down_velocity_mps=velocity_mps, up_velocity_mps=velocity_mps,
                  acceleration_mps2=math.inf, hold_s=hold_s)
    x0, _ = sample_presses([press], t, profile="ramp")
    return t, x0[0]


def study_key_outcome(
    x2_m: npt.ArrayLike, threshold_m: float, dt_s: float = STUDY_DT_S
) -> tuple[FloatArray, FloatArray]:
    """Trigger speed and hold time of key traces (last axis is time), the study's way.

    Returns (on_speed_mps, hold_s); on_speed is NaN and hold 0 where the key never goes beyond
    `threshold_m`.
    """
    x2 = np.atleast_2d(np.asarray(x2_m, dtype=np.float64))
    beyond = x2 > threshold_m
    hold = beyond.sum(axis=-1) * dt_s
    reached = beyond.any(axis=-1)
    # First sample beyond the trigger; the sample before it is the other side of the crossing.
    after = np.argmax(beyond, axis=-1)
    before = np.maximum(after - 1, 0)
    rows = np.arange(x2.shape[0])
    err_after = np.abs(x2[rows, after] - threshold_m)
    err_before = np.abs(x2[rows, before] - threshold_m)
    i = np.where(err_before <= err_after, before, after)
    # Forward difference needs sample i + 1 (exists unless the record ends at the crossing).
    i = np.minimum(i, x2.shape[-1] - 2)
    speed = (x2[rows, i + 1] - x2[rows, i]) / dt_s
    on_speed = np.where(reached, speed, np.nan)
    shape = np.shape(x2_m)[:-1]
    return on_speed.reshape(shape), hold.astype(np.float64).reshape(shape)


def study_outcomes(
    vacuum_kpa: npt.ArrayLike,
    velocity_mps: npt.ArrayLike,
    *,
    depth_m: float = 0.03,
    hold_s: float = 0.5,
    threshold_m: float = 0.005,
    params: MSDParams | None = None,
    dt_s: float = STUDY_DT_S,
) -> pd.DataFrame:
    """The study's outcomes (trigger speed and hold) of the linear model for many settings.

    Args:
        vacuum_kpa, velocity_mps: broadcast against each other with numpy rules, one row per
            element (C order). Equal shapes give paired settings; for a full grid pass
            `vac[:, None], vel[None, :]`.
        depth_m, hold_s: arm ramp depth and hold (the finger starts on the key).
        threshold_m: trigger depth of the key.
        params: model parameters; default `STUDY_SCRIPT_PARAMS` (the study's script values).
        dt_s: sampling step of the simulation (the study's 1 ms).

    Returns:
        DataFrame with columns vacuum_kpa, velocity_mps, on_speed_mps (NaN when the key never
        reaches the trigger), hold_s (time the key stays beyond the trigger).
    """
    model = STUDY_SCRIPT_PARAMS if params is None else params
    if not threshold_m > 0.0:
        raise ValueError(f"trigger threshold should be > 0 m, got {threshold_m}.")
    vac, vel = np.broadcast_arrays(
        np.asarray(vacuum_kpa, dtype=np.float64), np.asarray(velocity_mps, dtype=np.float64)
    )
    vac, vel = vac.ravel(), vel.ravel()
    if np.any(~(vel > 0.0)):
        raise ValueError(f"velocities should be > 0 m/s, got {vel[~(vel > 0.0)][0]}.")
    on_speed = np.full(vac.size, np.nan)
    hold = np.zeros(vac.size)
    systems = {p: state_space(model.at(p)) for p in np.unique(vac).tolist()}
    # One batched simulation per speed: all vacuum levels share its input and time grid.
    for v in np.unique(vel):
        rows = np.flatnonzero(vel == v)
        t, x0 = study_arm_input(depth_m, float(v), hold_s, dt_s)
        batch = _stack([systems[p] for p in vac[rows].tolist()])
        y = lsim_uniform(batch, t, x0[None, None, :])
        on_speed[rows], hold[rows] = study_key_outcome(y[:, 1, :], threshold_m, dt_s)
    return pd.DataFrame(
        {"vacuum_kpa": vac, "velocity_mps": vel, "on_speed_mps": on_speed, "hold_s": hold},
        columns=list(STUDY_OUTCOME_COLUMNS),
    )


def _stack(systems: list[StateSpace]) -> StateSpace:
    """Several systems of the same shape as one batched system."""
    first = systems[0]
    return StateSpace(
        np.stack([s.A for s in systems]),
        np.stack([s.B for s in systems]),
        np.stack([s.C for s in systems]),
        np.stack([s.D for s in systems]),
        first.states,
        first.inputs,
        first.outputs,
    )
