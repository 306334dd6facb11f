"""Per-keystroke features from trajectories: what the piano "sees" and how the stroke unfolded.

- key speed at the trigger depth: a digital piano times the key between two sensors near the
  bottom of travel, so the speed where the key passes the trigger depth is what sets the
  on-velocity (the study's readout);
- max key travel; contact time (fingertip on the key); time from motion start to the trigger
  (the lead `play` must schedule ahead of a note);
- how far the fingertip travelled before the key moved (`approach_distance_m`: the hover
  distance of a take whose commanded presses were not recorded), and how far the arm travelled
  before the finger was loaded at all (`unloaded_travel_m`: a finger resting on a key that is
  held by friction or a preload also travels before the key moves, but compressed).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.analysis.greybox.noise import noise_sigma_m
from pianobot.analysis.greybox.stages import (
    KEY_MOTION_THRESHOLD_M,
    fill_gaps,
    find_stages,
    first_crossing_s,
)

FloatArray = npt.NDArray[np.float64]

FEATURE_COLUMNS: tuple[str, ...] = (
    "key_speed_at_trigger_mps",
    "max_key_travel_m",
    "contact_time_s",
    "time_to_trigger_s",
)


@dataclass(frozen=True)
class KeystrokeFeatures:
    """Features of one keystroke (NaN where the keystroke did not reach the stage)."""

    key_speed_at_trigger_mps: float
    max_key_travel_m: float
    contact_time_s: float
    time_to_trigger_s: float

    def row(self) -> dict[str, float]:
        """As a flat dict with the table's column names."""
        return asdict(self)


def speed_at_s(t_s: FloatArray, x: FloatArray, t_at_s: float, half_window: int = 2) -> float:
    """Slope of x at time `t_at_s` from a local quadratic fit (robust to µm mocap noise)."""
    if not np.isfinite(t_at_s):
        return float("nan")
    i = int(np.clip(np.searchsorted(t_s, t_at_s), 1, t_s.size - 1))
    lo, hi = max(0, i - half_window - 1), min(t_s.size, i + half_window + 1)
    tt, xx = t_s[lo:hi] - t_at_s, x[lo:hi]
    good = np.isfinite(xx)
    if good.sum() < 2:
        return float("nan")
    degree = 2 if good.sum() >= 4 else 1
    coeffs = np.polyfit(tt[good], xx[good], degree)
    return float(coeffs[-2])  # derivative at tt = 0


def keystroke_features(
    t_s: npt.ArrayLike,
    x2_m: npt.ArrayLike,
    *,
    trigger_depth_m: float | None,
    x0_m: npt.ArrayLike | None = None,
    x1_m: npt.ArrayLike | None = None,
    distance_m: float | None = None,
) -> KeystrokeFeatures:
    """Features of one keystroke.

    `trigger_depth_m` is the key displacement where the piano triggers; None uses half of this
    keystroke's own travel (for traces whose key marker does not see the full dip).
    """
    t = np.asarray(t_s, dtype=np.float64)
    x2_raw = np.asarray(x2_m, dtype=np.float64)
    stages = find_stages(t, x2_raw, x0_m=x0_m, x1_m=x1_m, distance_m=distance_m)
    x2 = fill_gaps(t, x2_raw)
    if not np.isfinite(x2).any():
        nan = float("nan")
        return KeystrokeFeatures(nan, nan, nan, nan)
    head = x2[: max(3, x2.size // 20)]
    x2 = x2 - float(np.median(head[np.isfinite(head)]))
    travel = float(np.nanmax(x2))
    depth = 0.5 * travel if trigger_depth_m is None else trigger_depth_m
    t_trigger = first_crossing_s(t, x2, depth) if travel >= KEY_MOTION_THRESHOLD_M else np.nan
    speed = speed_at_s(t, x2, t_trigger)

    contact_end = stages.t_rest_s
    if x1_m is not None and distance_m is not None and distance_m > 0 and np.isfinite(stages.t_bottom_s):
        x1 = fill_gaps(t, np.asarray(x1_m, dtype=np.float64))
        closed = (x1 - float(np.median(x1[: max(3, x1.size // 20)]))) - x2
        after = np.flatnonzero((t >= stages.t_bottom_s) & (closed < distance_m - KEY_MOTION_THRESHOLD_M))
        if after.size:
            contact_end = float(t[after[0]])
    contact_time = contact_end - stages.t_contact_s
    return KeystrokeFeatures(
        key_speed_at_trigger_mps=speed,
        max_key_travel_m=max(travel, 0.0),
        contact_time_s=float(contact_time),
        time_to_trigger_s=float(t_trigger - stages.t_motion_s),
    )


def features_table(
    samples: pd.DataFrame,
    *,
    trigger_depth_m: float | None,
    source: str | None = None,
    distance_m: pd.Series | None = None,
) -> pd.DataFrame:
    """Features per trial from a long-form samples table (`trial_id, source, t_s, x0_m, x1_m, x2_m`).

    Args:
        samples: the store's samples table (or a subset).
        trigger_depth_m: the piano's trigger depth (see `keystroke_features`).
        source: use only this source ("mocap", "sim-truth", ...); None takes every row.
        distance_m: initial gap per trial_id (index trial_id), e.g. `trials.set_index("trial_id").distance_m`.
    Returns:
        One row per trial_id with `FEATURE_COLUMNS`.
    """
    frame = samples if source is None else samples[samples["source"] == source]
    rows = []
    for trial_id, group in frame.groupby("trial_id", sort=False):
        group = group.sort_values("t_s")
        gap = None if distance_m is None else float(distance_m.get(trial_id, np.nan))
        if gap is not None and not np.isfinite(gap):
            gap = None
        feats = keystroke_features(
            group["t_s"].to_numpy(float),
            group["x2_m"].to_numpy(float),
            trigger_depth_m=trigger_depth_m,
            x0_m=group["x0_m"].to_numpy(float) if "x0_m" in group else None,
            x1_m=group["x1_m"].to_numpy(float) if "x1_m" in group else None,
            distance_m=gap,
        )
        rows.append({"trial_id": trial_id, **feats.row()})
    return pd.DataFrame(rows, columns=["trial_id", *FEATURE_COLUMNS])


#: The key has started to move once it is this far down (well above a few µm of mocap noise,
#: well below the compression of a press) ...
KEY_ONSET_M = 5e-5
#: ... or this many σ of the key marker's noise, where that is more: in a capture with 30 µm of
#: marker noise, 50 µm is crossed by the noise alone in the first frames, and a hovering finger
#: then reads as resting on the key (each of four independent hover takes named a yielding finger).
ONSET_NOISE_SIGMAS = 5.0


def key_onset_m(batch: KeystrokeBatch) -> float:
    """The key travel read as its onset in `batch`: `KEY_ONSET_M`, or `ONSET_NOISE_SIGMAS` σ of
    the key marker's noise (second differences over the take) where that is more."""
    sigma = noise_sigma_m(batch.x2_m) if batch.x2_m.size else 0.0
    return max(KEY_ONSET_M, ONSET_NOISE_SIGMAS * sigma)


def approach_distance_m(batch: KeystrokeBatch) -> FloatArray:
    """Per keystroke, the fingertip's travel from rest until the key started to move (NaN where
    the key never moved or the fingertip was not tracked).

    Read where the key passes its onset (`key_onset_m`), between frames: by then the finger is
    slightly compressed, so this reads a little long (measured on independent takes: 0.2-0.4 mm
    over a 5 mm hover, 0.2 mm for a finger resting on the key).
    """
    level = key_onset_m(batch)
    out = np.full(batch.n, np.nan)
    for i in range(batch.n):
        t = batch.row_times_s(i)
        x2 = fill_gaps(t, batch.x2_m[i])
        x1 = fill_gaps(t, batch.x1_m[i])
        j = _onset_index(x2, level)
        if j is None or not np.isfinite(x1).any():
            continue
        f = (level - x2[j - 1]) / (x2[j] - x2[j - 1])
        out[i] = float(x1[j - 1] + f * (x1[j] - x1[j - 1]))
    return out


def _onset_index(x2: FloatArray, level: float) -> int | None:
    """First sample where the key is past `level` (None if never, or from the start)."""
    above = np.flatnonzero(x2 > level)
    return None if above.size == 0 or above[0] == 0 else int(above[0])


#: Hinge positions tried per keystroke by `unloaded_travel_m`.
_HINGES = 41


def unloaded_travel_m(batch: KeystrokeBatch) -> FloatArray:
    """Per keystroke, how far the arm travelled before the finger started to be compressed,
    up to where the key started to move (NaN without the arm, fingertip and key tracked).

    A finger in the air moves with the arm; once it touches the key, the arm–fingertip distance
    grows with the arm's travel (the finger's body spring is loaded). The distance is fitted as a
    hinge over the arm's travel: flat up to the contact, then a straight line. A finger resting
    on a key that friction or a preload holds still is loaded from the first millimetre (a hinge
    near 0), although its fingertip travels millimetres before the key moves. The finger's sway
    after the arm's acceleration blurs the hinge of a hovering finger (it reads 1-3 mm short
    over a 5 mm hover): this separates hovering from resting, it does not measure the hover.
    """
    level = key_onset_m(batch)
    out = np.full(batch.n, np.nan)
    for i in range(batch.n):
        t = batch.row_times_s(i)
        x0, x1, x2 = (fill_gaps(t, x[i]) for x in (batch.x0_m, batch.x1_m, batch.x2_m))
        j = _onset_index(x2, level)
        if j is None:
            continue
        u = x0[:j] - x0[0]
        d = (x0[:j] - x1[:j]) - (x0[0] - x1[0])  # how much the arm-fingertip distance grew
        ok = np.isfinite(u) & np.isfinite(d)
        u, d = u[ok], d[ok]
        if u.size < 4 or not np.max(u) > 0:
            continue
        best, hinge = np.inf, 0.0
        for h in np.linspace(0.0, float(np.max(u)), _HINGES):
            x = np.column_stack([np.ones_like(u), np.maximum(0.0, u - h)])
            coef, *_ = np.linalg.lstsq(x, d, rcond=None)
            r = d - x @ coef
            if float(r @ r) < best:
                best, hinge = float(r @ r), float(h)
        out[i] = hinge
    return out
