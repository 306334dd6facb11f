"""Where a model and the held-out keystrokes disagree: by stage, by parameter region, by outcome.

- **By stage** (trajectories): the study's five keystroke stages (`greybox.stages`: approach,
  contact, press, bottom, release), found from the *measured* traces so that every model is
  judged on the same frames; per stage and signal the residual RMS, bias and systematic part
  (mm) and its lag-1 autocorrelation (≈ 0 for noise, → 1 for a smooth misfit).
- **By region**: per vacuum level × speed tercile × acceleration × depth, the systematic
  position error (mm) or, with MIDI only, the on-velocity and hold errors and sound/silence
  mismatches.
- **By outcome** (MIDI): on-velocity error overall and its trend with speed, hold error, and
  which keystrokes the model sounds where the piano stayed silent or the reverse.
- **Against state** (trajectories): the key residual binned by key position, where a kink points
  at an end stop and a step at the key's velocity sign at friction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from pianobot.analysis.greybox.fitter import TRAJECTORY_CHANNELS, GreyBoxFit
from pianobot.analysis.greybox.noise import lag1_autocorrelation, rms, systematic_rms
from pianobot.analysis.greybox.stages import STAGE_NAMES, stage_labels

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Localisation:
    """Where the disagreement lives, on the held-out keystrokes (JSON-ready rows)."""

    stages: list[dict[str, Any]]
    regions: list[dict[str, Any]]
    outcomes: dict[str, Any]
    state: dict[str, Any]

    def worst_stages(self, fraction: float = 0.5) -> list[str]:
        """Stages whose systematic error is at least `fraction` of the worst stage's."""
        values: dict[str, float] = {}
        for row in self.stages:
            if math.isfinite(row["systematic_mm"]):
                values[row["stage"]] = max(values.get(row["stage"], 0.0), row["systematic_mm"])
        top = max(values.values(), default=0.0)
        return [s for s in STAGE_NAMES if s in values and top > 0 and values[s] >= fraction * top]

    def to_dict(self) -> dict[str, Any]:
        return {"by_stage": self.stages, "by_region": self.regions, "outcomes": self.outcomes,
                "against_state": self.state}


def _full(fit: GreyBoxFit, channel: str) -> FloatArray:
    """A channel's residuals back on the (n, T) frame grid (NaN elsewhere)."""
    res = fit.residuals_
    out = np.full((fit.batch.n, max(fit.batch.t_s.size, 1)), np.nan)
    if channel in res.values and res.values[channel].size:
        out[res.keystroke[channel], res.frame[channel]] = res.values[channel]
    return out


def by_stage(fit: GreyBoxFit, sigma_m: float, labels: npt.NDArray[np.int64]) -> list[dict[str, Any]]:
    """Residual statistics per stage and signal (mm)."""
    rows = []
    for k, stage in enumerate(STAGE_NAMES):
        for channel in TRAJECTORY_CHANNELS:
            full = _full(fit, channel)
            chunks = [full[i][labels[i] == k] for i in range(full.shape[0])]
            values = np.concatenate(chunks) if chunks else np.zeros(0)
            values = values[np.isfinite(values)]
            if values.size < 3:
                continue
            lags = [x for x in (lag1_autocorrelation(c) for c in chunks if c.size >= 3) if math.isfinite(x)]
            rows.append({"stage": stage, "signal": channel, "n": int(values.size), "rms_mm": 1e3 * rms(values),
                         "bias_mm": 1e3 * float(np.mean(values)), "systematic_mm": 1e3 * systematic_rms(values, sigma_m),
                         "lag1": float(np.mean(lags)) if lags else math.nan})
    return rows


def _terciles(values: FloatArray) -> FloatArray:
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return np.array([0.0, 1.0])
    edges = np.unique(np.quantile(finite, [0.0, 1 / 3, 2 / 3, 1.0]))
    return edges if edges.size >= 2 else np.array([finite.min(), finite.max() + 1e-9])


def by_region(fit: GreyBoxFit, sigma_m: float) -> list[dict[str, Any]]:
    """Errors per vacuum × speed tercile × acceleration × depth cell of the held-out keystrokes."""
    batch, res = fit.batch, fit.residuals_
    speed = batch.down_velocity_mps
    edges = _terciles(speed)
    cells: dict[tuple[float, int, float, float], list[int]] = {}
    for i in range(batch.n):
        s = speed[i]
        band = int(np.clip(np.searchsorted(edges, s, side="right") - 1, 0, edges.size - 2)) if math.isfinite(s) else -1
        key = (round(float(batch.vacuum_kpa[i]), 1), band, round(float(batch.acceleration_mps2[i]), 3),
               round(float(batch.depth_m[i]), 4))
        cells.setdefault(key, []).append(i)
    rows = []
    sounded = fit.prediction_.sounded
    for (vacuum, band, accel, depth), members in sorted(cells.items()):
        member = np.zeros(batch.n, dtype=bool)
        member[members] = True
        row: dict[str, Any] = {"vacuum_kpa": vacuum, "n": len(members),
                               "speed_mm_s": "n/a" if band < 0 else f"{1e3 * edges[band]:.0f}-{1e3 * edges[band + 1]:.0f}",
                               "acceleration_mps2": accel, "depth_mm": 1e3 * depth}
        traj = [res.values[c][member[res.keystroke[c]]] for c in TRAJECTORY_CHANNELS if c in res.values]
        flat = np.concatenate(traj) if traj else np.zeros(0)
        if flat.size:
            row["systematic_mm"] = 1e3 * systematic_rms(flat, sigma_m)
        for channel, scale, name in (("on_velocity", 1.0, "on_velocity_rms"), ("hold_s", 1e3, "hold_rms_ms")):
            if channel in res.values:
                values = res.values[channel][member[res.keystroke[channel]]]
                row[name] = scale * rms(values) if values.size else math.nan
        if np.isfinite(batch.sounded[member]).any():
            row["sound_wrong"] = int(np.sum((batch.sounded[member] == 1.0) != sounded[member]))
        rows.append(row)
    return rows


def outcomes(fit: GreyBoxFit) -> dict[str, Any]:
    """MIDI outcome errors of the held-out keystrokes (model − measured)."""
    batch, pred, res = fit.batch, fit.prediction_, fit.residuals_
    if not batch.has_midi:
        return {}
    out: dict[str, Any] = {}
    if "on_velocity" in res.values and res.values["on_velocity"].size >= 3:
        dv, rows = res.values["on_velocity"], res.keystroke["on_velocity"]
        speed = batch.down_velocity_mps[rows]
        slope = float(np.polyfit(speed, dv, 1)[0]) if np.ptp(speed) > 0 else math.nan
        out.update({"on_velocity_rms": rms(dv), "on_velocity_bias": float(np.mean(dv)),
                    "on_velocity_slope_per_mps": slope})
    if "hold_s" in res.values and res.values["hold_s"].size:
        out["hold_rms_ms"] = 1e3 * rms(res.values["hold_s"])
        out["hold_bias_ms"] = 1e3 * float(np.mean(res.values["hold_s"]))
    known = np.isfinite(batch.sounded)
    heard = batch.sounded == 1.0
    out["silent_measured_sounded_model"] = int(np.sum(known & ~heard & pred.sounded))
    out["sounded_measured_silent_model"] = int(np.sum(known & heard & ~pred.sounded))
    return out


def _binned(x: FloatArray, y: FloatArray, bins: int = 8) -> list[dict[str, float]]:
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if x.size < 2 * bins:
        return []
    edges = np.unique(np.quantile(x, np.linspace(0.0, 1.0, bins + 1)))
    index = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, edges.size - 2)
    return [{"x_mm": 1e3 * float(np.mean(x[index == b])), "mean_mm": 1e3 * float(np.mean(y[index == b])),
             "n": int(np.sum(index == b))} for b in range(edges.size - 1) if np.any(index == b)]


def against_state(fit: GreyBoxFit) -> dict[str, Any]:
    """Key residual binned by key position; its step across the key's velocity sign."""
    batch = fit.batch
    if not batch.has_motion or fit.prediction_.v2_mps.size == 0:
        return {}
    r2 = _full(fit, "x2")
    x2 = fit.prediction_.x2_m
    v2 = fit.prediction_.v2_mps
    ok = np.isfinite(r2) & np.isfinite(v2)
    down, up = r2[ok & (v2 > 1e-4)], r2[ok & (v2 < -1e-4)]
    step = float(np.mean(down) - np.mean(up)) if down.size >= 3 and up.size >= 3 else math.nan
    return {"vs_key_position": _binned(x2[ok], r2[ok]), "step_at_key_velocity_sign_mm": 1e3 * step}


def localise(fit: GreyBoxFit, sigma_m: float) -> Localisation:
    """Every localisation statistic of a model evaluated on the held-out keystrokes."""
    batch = fit.batch
    stages: list[dict[str, Any]] = []
    if batch.has_motion:
        times = batch.t_s[None, :] + batch.t_offset_s[:, None]
        labels = stage_labels(times, batch.x2_m, batch.x0_m, batch.x1_m, batch.start_gap_m)
        stages = by_stage(fit, sigma_m, labels)
    return Localisation(stages, by_region(fit, sigma_m), outcomes(fit), against_state(fit))
