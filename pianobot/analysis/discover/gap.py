"""The held-out gap: how far a model is from keystrokes it was not fitted to.

With trajectories the gap is the systematic position error √(RMS² − σ²) over the fingertip and
key frames of the held-out keystrokes (rest offsets profiled out, as in the fit), in metres
(reports print mm). With MIDI only it is the outcome error: on-velocity (MIDI units, the
rounding floor removed), hold (s), and keystrokes the model sounds where the piano stayed
silent or the reverse. A single figure that every candidate is ranked by (`score`) puts each
measure on the scale of the base model's own error, so it is 1 for the base model and shrinks
as an effect explains the data.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from pianobot.analysis.greybox.fitter import MIDI_FLOORS, TRAJECTORY_CHANNELS, Residuals
from pianobot.analysis.greybox.noise import rms, systematic_rms

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Gap:
    """Held-out disagreement of one model (NaN where a measure does not apply)."""

    position_m: float  # systematic position error (x1 and x2 frames)
    position_rms_m: float
    sigma_m: float  # position noise level of the held-out residuals
    on_velocity: float  # systematic on-velocity error (MIDI units)
    hold_s: float  # RMS hold error (s)
    sounded_mismatch: int  # keystrokes where model and piano disagree on sound or silence
    n_keystrokes: int
    per_keystroke: dict[str, FloatArray]  # measure -> (n,) each held-out keystroke's |error|

    @property
    def primary_name(self) -> str:
        """What `primary` measures: position with trajectories, else on-velocity."""
        return "position_m" if math.isfinite(self.position_m) else "on_velocity"

    @property
    def primary(self) -> float:
        return self.position_m if math.isfinite(self.position_m) else self.on_velocity

    def text(self, *, short: bool = False) -> str:
        """The gap in words with units (mm for positions); `short` for a table cell."""
        if math.isfinite(self.position_m):
            if short:
                return f"{1e3 * self.position_m:.3g} mm"
            return f"{1e3 * self.position_m:.3g} mm systematic (RMS {1e3 * self.position_rms_m:.3g} mm, noise {1e3 * self.sigma_m:.2g} mm)"
        parts = []
        if math.isfinite(self.on_velocity):
            parts.append(f"vel {self.on_velocity:.2g}" if short else f"on-velocity {self.on_velocity:.3g} MIDI")
        if math.isfinite(self.hold_s):
            parts.append(f"hold {1e3 * self.hold_s:.3g} ms")
        parts.append(f"{self.sounded_mismatch} sound" if short
                     else f"{self.sounded_mismatch} of {self.n_keystrokes} sound/silence wrong")
        return ", ".join(parts)

    def to_dict(self) -> dict[str, Any]:
        return {"primary_name": self.primary_name, "primary": self.primary, "position_m": self.position_m,
                "position_mm": 1e3 * self.position_m, "position_rms_m": self.position_rms_m, "sigma_m": self.sigma_m,
                "on_velocity": self.on_velocity, "hold_s": self.hold_s, "sounded_mismatch": self.sounded_mismatch,
                "n_keystrokes": self.n_keystrokes}


def held_out_gap(res: Residuals, n: int, sigma_m: float, sounded: FloatArray, model_sounded: npt.NDArray[np.bool_],
                 read: npt.NDArray[np.bool_] | bool = True) -> Gap:
    """The gap of one model's held-out residuals (natural units, `Residuals` of the fitter)."""
    traj = [res.values[c] for c in TRAJECTORY_CHANNELS if c in res.values and res.values[c].size]
    flat = np.concatenate(traj) if traj else np.zeros(0)
    per: dict[str, FloatArray] = {}
    if flat.size:
        rows = np.concatenate([res.keystroke[c] for c in TRAJECTORY_CHANNELS if c in res.values and res.values[c].size])
        sq = np.bincount(rows, flat**2, minlength=n)
        count = np.bincount(rows, minlength=n).astype(np.float64)
        per["position_m"] = np.asarray(np.where(count > 0, np.sqrt(sq / np.maximum(count, 1.0)), np.nan), dtype=np.float64)
    for channel, measure in (("on_velocity", "on_velocity"), ("hold_s", "hold_s")):
        v = res.values.get(channel)
        if v is not None and v.size:
            each = np.full(n, np.nan)
            each[res.keystroke[channel]] = np.abs(v)
            per[measure] = each
    # Sound and silence are judged only where the model read the piano (the commanded drive).
    known = np.isfinite(sounded) & read
    mismatch = int(np.sum(known & ((sounded == 1.0) != model_sounded)))
    velocity = res.values.get("on_velocity")
    hold = res.values.get("hold_s")
    return Gap(
        position_m=systematic_rms(flat, sigma_m) if flat.size else math.nan,
        position_rms_m=rms(flat) if flat.size else math.nan,
        sigma_m=sigma_m if flat.size else math.nan,
        on_velocity=systematic_rms(velocity, MIDI_FLOORS["on_velocity"]) if velocity is not None and velocity.size else math.nan,
        hold_s=rms(hold) if hold is not None and hold.size else math.nan,
        sounded_mismatch=mismatch,
        n_keystrokes=n,
        per_keystroke=per,
    )


#: Held-out MIDI outcome errors that are something to explain (systematic on-velocity in MIDI
#: units, RMS hold in s): below them an outcome is at the level of the piano's rounding and clock.
EXPLAIN_LEVELS: dict[str, float] = {"on_velocity": 0.5, "hold_s": 0.01}


def above_noise(gap: Gap) -> tuple[str, ...]:
    """The MIDI outcomes whose held-out error is something to explain (`EXPLAIN_LEVELS`; any
    sound/silence mismatch is)."""
    out = tuple(name for name, level in EXPLAIN_LEVELS.items()
                if math.isfinite(getattr(gap, name)) and getattr(gap, name) > level)
    return out + (("sounded_mismatch",) if gap.sounded_mismatch > 0 else ())


def _ratios(gap: Gap, reference: Gap) -> dict[str, float]:
    """after/before of every measure above its floor in the reference."""
    out = {}
    for name, floor in (("position_m", 0.0), ("on_velocity", 0.0), ("hold_s", 0.0)):
        ref, mine = getattr(reference, name), getattr(gap, name)
        if math.isfinite(ref) and ref > floor and math.isfinite(mine):
            out[name] = mine / ref
    if reference.sounded_mismatch > 0:
        out["sounded_mismatch"] = gap.sounded_mismatch / reference.sounded_mismatch
    return out


def score(gap: Gap, reference: Gap) -> tuple[float, str]:
    """(the gap on the reference's scale, 1 = as bad; the measure it is read on); see the module
    docstring. With several measures (MIDI outcomes) the one the model improves most counts,
    provided the held-out likelihood over all of them improves too (the geometric mean of the
    ratios is below 1): a large gain in one measure may outweigh a small loss in another, a
    gain bought with a larger loss may not. The measure read is one the reference had something
    to explain in (`above_noise`), where there is one: an on-velocity error already at the
    rounding level (a soft piano's notes at 1-3) "shrinks" by chance, and its keystrokes then
    said whether a model that fixed the hold was consistent."""
    ratios = _ratios(gap, reference)
    if not ratios:
        return math.nan, ""
    if len(ratios) > 1:
        overall = float(np.exp(np.mean(np.log(np.clip(list(ratios.values()), 1e-3, None)))))
        if overall >= 1.0:
            return overall, "all outcomes"
    # A position gap is read as it is (its noise is already removed); MIDI outcomes above theirs.
    explained = above_noise(reference) + (("position_m",) if math.isfinite(reference.position_m) else ())
    readable = [k for k in ratios if k in explained] or list(ratios)
    best = min(readable, key=lambda k: ratios[k])
    return ratios[best], best


def consistency(after: Gap, before: Gap, measure: str, tolerance: float = 0.02) -> float:
    """Fraction of held-out keystrokes the model changes by more than `tolerance` (of the
    measure's overall level) that it improves, on one measure."""
    a, b = after.per_keystroke.get(measure), before.per_keystroke.get(measure)
    if a is None or b is None:
        return 1.0 if measure == "sounded_mismatch" else 0.0
    ok = np.isfinite(a) & np.isfinite(b)
    level = float(np.sqrt(np.mean(b[ok] ** 2))) if ok.any() else 0.0
    changed = ok & (np.abs(a - b) > tolerance * level)
    if not changed.any():
        return 0.0
    return float(np.mean(a[changed] < b[changed]))


def measures(gap: Gap, reference: Gap) -> Mapping[str, tuple[float, float]]:
    """Each applicable measure's (reference, this) pair, for reports."""
    out = {}
    for name in ("position_m", "on_velocity", "hold_s"):
        ref, mine = getattr(reference, name), getattr(gap, name)
        if math.isfinite(ref):
            out[name] = (ref, mine)
    if reference.sounded_mismatch or gap.sounded_mismatch:
        out["sounded_mismatch"] = (float(reference.sounded_mismatch), float(gap.sounded_mismatch))
    return out
