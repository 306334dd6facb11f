"""Localise where the model and the measurement disagree: by phase, by region, against state.

Every statistic is computed on the keystrokes it is given (discovery passes the held-out ones).
The residual is measured − predicted, per signal (arm, fingertip, key), in metres; MIDI outcome
residuals are in MIDI velocity units and seconds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from pianobot.analysis.discover.data import PHASES, SIGNALS, Keystroke, Prediction
from pianobot.analysis.discover.noise import (
    lag1_autocorrelation,
    noise_sigma,
    quantisation_sigma,
    rms,
    systematic_rms,
)

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Gap:
    """Held-out disagreement: systematic position error and MIDI outcome errors."""

    position_m: float  # √(RMS² − σ²) over every measured position sample
    position_rms_m: float
    sigma_m: float  # position noise level estimated from the data
    on_velocity: float  # RMS of on-velocity residual over keystrokes both sounded
    t_on_s: float
    sounded_mismatch: int  # keystrokes where model and piano disagree on sound / silence

    @property
    def primary(self) -> float:
        """The figure discovery shrinks: position when there is motion capture, else MIDI."""
        return self.position_m if np.isfinite(self.position_m) else self.on_velocity

    @property
    def primary_name(self) -> str:
        """What `primary` measures."""
        return "position_m" if np.isfinite(self.position_m) else "on_velocity"

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready values."""
        return {
            "primary": self.primary,
            "primary_name": self.primary_name,
            "position_m": self.position_m,
            "position_rms_m": self.position_rms_m,
            "sigma_m": self.sigma_m,
            "on_velocity": self.on_velocity,
            "t_on_s": self.t_on_s,
            "sounded_mismatch": self.sounded_mismatch,
        }


def position_residuals(
    keystrokes: Sequence[Keystroke], predictions: Sequence[Prediction]
) -> list[FloatArray]:
    """Per keystroke, the (3, n) residual measured − predicted (NaN where not measured)."""
    return [k.x_m - p.x_m for k, p in zip(keystrokes, predictions, strict=True)]


def estimate_sigma(residuals: Sequence[FloatArray]) -> float:
    """Position noise level from 4th differences of every signal of every keystroke."""
    return noise_sigma([r[s] for r in residuals for s in range(r.shape[0])])


def _midi_pairs(
    keystrokes: Sequence[Keystroke], predictions: Sequence[Prediction], field: str
) -> FloatArray:
    values = [
        getattr(k, field) - getattr(p, field)
        for k, p in zip(keystrokes, predictions, strict=True)
        if k.sounded and p.sounded
    ]
    return np.array(values, dtype=np.float64)


def gap(
    keystrokes: Sequence[Keystroke],
    predictions: Sequence[Prediction],
    sigma_m: float | None = None,
) -> Gap:
    """The held-out gap; `sigma_m` defaults to the noise estimated from these residuals."""
    residuals = position_residuals(keystrokes, predictions)
    flat = np.concatenate([r.ravel() for r in residuals]) if residuals else np.empty(0)
    has_motion = bool(np.isfinite(flat).any())
    sigma = estimate_sigma(residuals) if sigma_m is None and has_motion else (sigma_m or 0.0)
    mismatch = sum(
        1
        for k, p in zip(keystrokes, predictions, strict=True)
        if k.sounded is not None and bool(k.sounded) != p.sounded
    )
    dv = _midi_pairs(keystrokes, predictions, "on_velocity")
    # The piano rounds velocities to integers: that floor is noise, not a model error.
    on_velocity = systematic_rms(dv, quantisation_sigma()) if dv.size else float("nan")
    return Gap(
        position_m=systematic_rms(flat, sigma) if has_motion else float("nan"),
        position_rms_m=rms(flat) if has_motion else float("nan"),
        sigma_m=float(sigma) if has_motion else float("nan"),
        on_velocity=on_velocity,
        t_on_s=rms(_midi_pairs(keystrokes, predictions, "t_on_s")),
        sounded_mismatch=mismatch,
    )


def by_phase(
    keystrokes: Sequence[Keystroke], predictions: Sequence[Prediction], sigma_m: float
) -> list[dict[str, Any]]:
    """Residual RMS, bias, systematic RMS and lag-1 autocorrelation per phase and signal."""
    rows: list[dict[str, Any]] = []
    residuals = position_residuals(keystrokes, predictions)
    for phase_index, phase in enumerate(PHASES):
        for s, signal in enumerate(SIGNALS):
            chunks = [
                r[s][p.phase == phase_index] for r, p in zip(residuals, predictions, strict=True)
            ]
            values = np.concatenate(chunks) if chunks else np.empty(0)
            values = values[np.isfinite(values)]
            if values.size < 3:
                continue
            lags = [lag1_autocorrelation(c) for c in chunks if c.size >= 3]
            lags = [x for x in lags if np.isfinite(x)]
            rows.append(
                {
                    "phase": phase,
                    "signal": signal,
                    "n": int(values.size),
                    "rms_m": rms(values),
                    "bias_m": float(np.mean(values)),
                    "systematic_m": systematic_rms(values, sigma_m),
                    "lag1": float(np.mean(lags)) if lags else float("nan"),
                }
            )
    return rows


def _speed_bin(speed_mps: float, edges: FloatArray) -> str:
    i = int(np.searchsorted(edges, speed_mps, side="right")) - 1
    i = min(max(i, 0), edges.size - 2)
    return f"{edges[i] * 1e3:.0f}-{edges[i + 1] * 1e3:.0f} mm/s"


def by_region(
    keystrokes: Sequence[Keystroke], predictions: Sequence[Prediction], sigma_m: float
) -> list[dict[str, Any]]:
    """Systematic key error and on-velocity error per vacuum × speed tercile × depth cell."""
    speeds = np.array([k.press.down_velocity_mps for k in keystrokes])
    if speeds.size == 0:
        return []
    edges = np.unique(np.quantile(speeds, [0.0, 1 / 3, 2 / 3, 1.0]))
    if edges.size < 2:
        edges = np.array([speeds.min(), speeds.max() + 1e-9])
    cells: dict[tuple[float, str, float], list[int]] = {}
    for i, k in enumerate(keystrokes):
        key = (
            round(k.vacuum_kpa, 1),
            _speed_bin(k.press.down_velocity_mps, edges),
            round(k.press.depth_m, 4),
        )
        cells.setdefault(key, []).append(i)
    rows = []
    for (vacuum, speed, depth), members in sorted(cells.items()):
        ks = [keystrokes[i] for i in members]
        ps = [predictions[i] for i in members]
        g = gap(ks, ps, sigma_m=sigma_m)
        rows.append(
            {
                "vacuum_kpa": vacuum,
                "speed": speed,
                "depth_m": depth,
                "n": len(members),
                "position_m": g.position_m,
                "on_velocity": g.on_velocity,
            }
        )
    return rows


def _binned_means(x: FloatArray, y: FloatArray, bins: int = 8) -> list[dict[str, float]]:
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if x.size < 2 * bins:
        return []
    edges = np.unique(np.quantile(x, np.linspace(0.0, 1.0, bins + 1)))
    index = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, edges.size - 2)
    out = []
    for b in range(edges.size - 1):
        sel = index == b
        if sel.any():
            out.append(
                {"x": float(np.mean(x[sel])), "mean": float(np.mean(y[sel])), "n": int(sel.sum())}
            )
    return out


def _step(y: FloatArray, condition: npt.NDArray[np.bool_]) -> float:
    ok = np.isfinite(y)
    a, b = y[ok & condition], y[ok & ~condition]
    if a.size < 3 or b.size < 3:
        return float("nan")
    return float(np.mean(a) - np.mean(b))


def _kink(binned: list[dict[str, float]]) -> dict[str, float] | None:
    """Where the binned residual curve bends most (largest change of slope)."""
    if len(binned) < 3:
        return None
    x = np.array([b["x"] for b in binned])
    y = np.array([b["mean"] for b in binned])
    slopes = np.diff(y) / np.maximum(np.diff(x), 1e-12)
    bend = np.abs(np.diff(slopes))
    i = int(np.argmax(bend))
    return {"at": float(x[i + 1]), "slope_change": float(slopes[i + 1] - slopes[i])}


def best_time_shift_s(
    keystrokes: Sequence[Keystroke], predictions: Sequence[Prediction], max_shift_s: float = 0.05
) -> float:
    """The time shift of the prediction that best matches the measured key (a lag indicator)."""
    shifts = np.linspace(-max_shift_s, max_shift_s, 41)
    costs = np.zeros_like(shifts)
    for k, p in zip(keystrokes, predictions, strict=True):
        if k.t_s.size < 4:
            continue
        for j, shift in enumerate(shifts):
            for s in range(3):
                shifted = np.interp(k.t_s, k.t_s + shift, p.x_m[s])
                r = k.x_m[s] - shifted
                costs[j] += float(np.nansum(r * r))
    return float(shifts[int(np.argmin(costs))]) if costs.any() else 0.0


def against_state(
    keystrokes: Sequence[Keystroke], predictions: Sequence[Prediction]
) -> dict[str, Any]:
    """Key residual against key position, velocity, compression and contact-force sign.

    Steps at a velocity sign point to friction, at a contact-force sign to adhesion; a kink in
    key position points to an end stop; a best time shift away from zero to a lag or delay.
    """
    residuals = position_residuals(keystrokes, predictions)
    if not residuals:
        return {}
    r2 = np.concatenate([r[2] for r in residuals])
    x2 = np.concatenate([p.x_m[2] for p in predictions])
    v2 = np.concatenate([p.v2_mps for p in predictions])
    comp = np.concatenate([p.compression_m for p in predictions])
    force = np.concatenate([p.contact_force_n for p in predictions])
    in_contact = comp > 0
    by_position = _binned_means(x2[in_contact], r2[in_contact])
    return {
        "vs_key_position": by_position,
        "vs_key_velocity": _binned_means(v2, r2),
        "vs_compression": _binned_means(comp[in_contact], r2[in_contact]),
        "kink_in_key_position": _kink(by_position),
        "step_at_key_velocity_sign_m": _step(r2, v2 > 0),
        "step_at_contact_force_sign_m": _step(r2[in_contact], force[in_contact] < 0),
        "best_time_shift_s": best_time_shift_s(keystrokes, predictions),
    }


def outcomes(keystrokes: Sequence[Keystroke], predictions: Sequence[Prediction]) -> dict[str, Any]:
    """MIDI outcome residuals: velocity (and its trend with speed), note-on time, hold, sound."""
    both = [(k, p) for k, p in zip(keystrokes, predictions, strict=True) if k.sounded and p.sounded]
    dv = np.array([k.on_velocity - p.on_velocity for k, p in both])
    speeds = np.array([k.press.down_velocity_mps for k, _ in both])
    slope = (
        float(np.polyfit(speeds, dv, 1)[0]) if dv.size >= 3 and np.ptp(speeds) > 0 else float("nan")
    )
    dt = np.array([k.t_on_s - p.t_on_s for k, p in both])
    dh = np.array([k.hold_s - p.hold_s for k, p in both])
    recorded = [
        (k, p) for k, p in zip(keystrokes, predictions, strict=True) if k.sounded is not None
    ]
    return {
        "n_sounded_both": len(both),
        "on_velocity_rms": rms(dv),
        "on_velocity_bias": float(np.mean(dv)) if dv.size else float("nan"),
        "on_velocity_slope_per_mps": slope,
        "t_on_rms_s": rms(dt),
        "t_on_bias_s": float(np.nanmean(dt)) if np.isfinite(dt).any() else float("nan"),
        "hold_rms_s": rms(dh),
        "silent_measured_sounded_model": sum(1 for k, p in recorded if not k.sounded and p.sounded),
        "sounded_measured_silent_model": sum(1 for k, p in recorded if k.sounded and not p.sounded),
    }


@dataclass(frozen=True)
class Localisation:
    """Where the disagreement lives, on the keystrokes it was computed from."""

    gap: Gap
    phases: list[dict[str, Any]]
    regions: list[dict[str, Any]]
    state: dict[str, Any]
    outcome: dict[str, Any]

    def worst_phases(self, fraction: float = 0.5) -> list[str]:
        """Phases whose systematic error is at least `fraction` of the worst phase's."""
        values: dict[str, float] = {}
        for row in self.phases:
            value = row["systematic_m"]
            if np.isfinite(value):
                values[row["phase"]] = max(values.get(row["phase"], 0.0), value)
        if not values:
            return []
        top = max(values.values())
        return [p for p in PHASES if p in values and top > 0 and values[p] >= fraction * top]

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready values."""
        return {
            "gap": self.gap.to_dict(),
            "by_phase": self.phases,
            "by_region": self.regions,
            "against_state": self.state,
            "outcomes": self.outcome,
        }


def localise(
    keystrokes: Sequence[Keystroke], predictions: Sequence[Prediction], sigma_m: float | None = None
) -> Localisation:
    """Every localisation statistic for these keystrokes."""
    g = gap(keystrokes, predictions, sigma_m)
    sigma = g.sigma_m if np.isfinite(g.sigma_m) else 0.0
    has_motion = np.isfinite(g.position_m)
    return Localisation(
        gap=g,
        phases=by_phase(keystrokes, predictions, sigma) if has_motion else [],
        regions=by_region(keystrokes, predictions, sigma),
        state=against_state(keystrokes, predictions) if has_motion else {},
        outcome=outcomes(keystrokes, predictions),
    )
