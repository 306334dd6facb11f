"""The piano's readout identified from keystrokes with both a key trajectory and MIDI.

A digital piano times the key between two sensors near the bottom of its travel and maps that
speed to a note-on velocity. Given measured key trajectories x2 and the velocities the piano
reported, this finds

- the trigger depth d (the lower sensor): the key's speed between the two sensors, the time the
  key takes from d − gap to d (the prior piano's sensor spacing), explains the velocities best
  (for each candidate depth the velocity map is fitted and scored by its RMS error in MIDI
  units). This is what the piano itself measures; a local slope of the 120 Hz key trace at one
  depth is not (a slow key decelerates across the sensors, and the slope misreads it);
- the velocity map v = 127·(s / s_full)^γ (clipped to 1–127): a straight line through the
  origin in log–log, fitted by least squares on log v (velocities ≥ 126 are left out: clipped).

`ReadoutFit.piano(prior)` turns the result into the model file's `PianoParams`: the lower
sensor at d, the upper one the prior's spacing above it; γ ≠ 1 becomes the `velocity_curve`
effect.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.analysis.greybox.stages import fill_gaps, first_crossing_s
from pianobot.physics.piano import PianoParams, on_velocity_from_speed

FloatArray = npt.NDArray[np.float64]
MIN_TRIALS = 5


@dataclass(frozen=True)
class ReadoutFit:
    """Identified trigger depth and key-speed → velocity map."""

    trigger_depth_m: float
    full_scale_speed_mps: float
    curve_exponent: float
    rmse_velocity: float  # MIDI units, at the chosen depth
    n_trials: int
    depth_scan: pd.DataFrame  # depth_m, rmse_velocity, n (every candidate)
    linear_rmse_velocity: float = math.nan  # the best straight line through the origin (γ = 1) there

    def piano(self, prior: PianoParams) -> PianoParams:
        """The prior piano with its lower sensor at the trigger depth and the fitted full scale."""
        lower = self.trigger_depth_m
        upper = _upper_sensor_m(lower, prior)
        release = min(prior.release_m, 0.9 * lower)
        return prior.replace(upper_sensor_m=upper, lower_sensor_m=lower, release_m=release,
                             full_scale_speed_mps=self.full_scale_speed_mps,
                             curve_exponent=self.curve_exponent, curve_saturation=0.0)

    def to_dict(self) -> dict[str, float | int]:
        """Plain values for JSON and the model file."""
        return {"trigger_depth_m": self.trigger_depth_m, "full_scale_speed_mps": self.full_scale_speed_mps,
                "curve_exponent": self.curve_exponent, "rmse_velocity": self.rmse_velocity,
                "n_trials": self.n_trials}


def _upper_sensor_m(lower_m: float, prior: PianoParams) -> float:
    """The upper sensor: the prior's spacing above the lower one (at least a quarter of its depth)."""
    return max(lower_m - (prior.lower_sensor_m - prior.upper_sensor_m), 0.25 * lower_m)


def _speeds_at(batch: KeystrokeBatch, rows: npt.NDArray[np.intp], depth_m: float) -> FloatArray:
    """Each row's key speed between the sensors (upper → lower at `depth_m`), from the times the
    measured key trace crosses them (interpolated between frames)."""
    upper = _upper_sensor_m(depth_m, PianoParams())
    out = np.full(rows.size, np.nan)
    for j, i in enumerate(rows):
        t = batch.row_times_s(i)
        x = fill_gaps(t, batch.x2_m[i])
        t_up, t_lo = first_crossing_s(t, x, upper), first_crossing_s(t, x, depth_m)
        if t_lo > t_up:
            out[j] = (depth_m - upper) / (t_lo - t_up)
    return out


def _power_law(speed: FloatArray, velocity: FloatArray) -> tuple[float, float, float]:
    """(s_full, γ, RMSE in MIDI units) of v = 127 (s/s_full)^γ fitted in log–log."""
    ok = np.isfinite(speed) & (speed > 0) & (velocity >= 1) & (velocity < 126)
    if ok.sum() < MIN_TRIALS:
        return math.nan, math.nan, math.inf
    ls, lv = np.log(speed[ok]), np.log(velocity[ok] / 127.0)
    gamma, c = np.polyfit(ls, lv, 1)
    if not gamma > 0:
        return math.nan, math.nan, math.inf
    s_full = math.exp(-c / gamma)
    curve = PianoParams(full_scale_speed_mps=s_full, curve_exponent=float(gamma))  # no saturation
    pred = on_velocity_from_speed(speed[ok], curve, rounded=False)
    return s_full, float(gamma), float(np.sqrt(np.mean((pred - velocity[ok]) ** 2)))


def fit_readout(batch: KeystrokeBatch, trials: pd.DataFrame, *, n_depths: int = 40) -> ReadoutFit | None:
    """Fit trigger depth and velocity map; None when fewer than `MIN_TRIALS` sounded trials
    have both a key trajectory and an on-velocity.

    `trials` needs `trial_id` (as in the batch) and `on_velocity`.
    """
    if "on_velocity" not in trials or trials.empty:
        return None
    velocity = trials.set_index("trial_id")["on_velocity"].astype(float)
    velocity = velocity[~velocity.index.duplicated()]
    v = np.array([velocity.get(tid, np.nan) for tid in batch.trial_id], dtype=np.float64)
    rows = np.flatnonzero(np.isfinite(v))
    if rows.size < MIN_TRIALS:
        return None
    travel = np.nanmax(batch.x2_m[rows], axis=1)
    # The trigger lies above the shallowest sounded keystroke's bottom (it sounded).
    top = float(np.nanpercentile(travel, 5))
    if not top > 0:
        return None
    depths = np.linspace(0.05 * top, 0.95 * top, n_depths)
    scan = []
    for d in depths:
        s_full, gamma, rmse = _power_law(_speeds_at(batch, rows, float(d)), v[rows])
        scan.append({"depth_m": float(d), "rmse_velocity": rmse, "full_scale_speed_mps": s_full,
                     "curve_exponent": gamma})
    frame = pd.DataFrame(scan)
    best = scan[int(np.argmin(frame["rmse_velocity"].to_numpy(dtype=np.float64)))]
    if not math.isfinite(best["rmse_velocity"]):
        return None
    speeds = _speeds_at(batch, rows, best["depth_m"])
    return ReadoutFit(best["depth_m"], best["full_scale_speed_mps"], best["curve_exponent"],
                      best["rmse_velocity"], int(rows.size), frame, _line_rmse(speeds, v[rows]))


def _line_rmse(speed: FloatArray, velocity: FloatArray) -> float:
    """RMSE (MIDI units) of the best v = 127·s/s_full (γ = 1), fitted in log space."""
    ok = np.isfinite(speed) & (speed > 0) & (velocity >= 1) & (velocity < 126)
    if ok.sum() < 2:
        return math.nan
    log_full = float(np.mean(np.log(speed[ok]) - np.log(velocity[ok] / 127.0)))
    line = PianoParams(full_scale_speed_mps=math.exp(log_full), curve_exponent=1.0)
    pred = on_velocity_from_speed(speed[ok], line, rounded=False)
    return float(np.sqrt(np.mean((pred - velocity[ok]) ** 2)))
