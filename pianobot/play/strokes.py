"""A model's keystroke outcomes tabulated over down velocity, for fast per-note inverses.

For one stroke configuration (vacuum and a `StrokeGeometry`: hover distance, depth,
acceleration, up velocity) the planner asks the model once for on-velocity, silence, lead
(motion start → note-on) and MIDI hold at a grid of down velocities and two holds, then answers
every note by interpolation (vectorised: a 20,000-note song costs a few array operations). The
loudness is inverted by the predictor contract's one inversion (`LoudnessCurve`: monotone, the
slowest speed that reaches a loudness).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.analysis.learn.predictors import LoudnessCurve, StrokePredictor
from pianobot.play.geometry import StrokeGeometry, envelope_limits, fastest_geometry, vacuum_levels
from pianobot.play.settings import PlaySettings
from pianobot.spec import RigSpec

FloatArray = npt.NDArray[np.float64]

# When the model's hold does not respond to the commanded hold (a learned model trained at one
# hold), holding the arm down longer keeps the key down just as much longer.
FALLBACK_HOLD_SLOPE = 1.0


@dataclass(frozen=True)
class StrokeTable:
    """Outcomes of one stroke configuration over a grid of down velocities."""

    vacuum_kpa: float
    geometry: StrokeGeometry
    settings: PlaySettings
    speeds_mps: FloatArray
    velocity: FloatArray  # monotone envelope of the predicted on-velocity (NaN where silent)
    lead_s: FloatArray
    hold0_s: FloatArray  # MIDI hold at zero arm hold
    hold_slope: FloatArray  # d(MIDI hold)/d(arm hold)
    busy0_s: FloatArray  # motion start → free for the next move at zero hold (press + recovery)

    @classmethod
    def build(cls, predictor: StrokePredictor, vacuum_kpa: float, geometry: StrokeGeometry,
              settings: PlaySettings, max_down_velocity_mps: float,
              min_down_velocity_mps: float | None = None) -> StrokeTable:
        """Ask `predictor` for the outcomes at `settings.speeds` down velocities up to the cap
        (from `min_down_velocity_mps`, default the settings' slowest)."""
        floor = settings.min_down_velocity_mps if min_down_velocity_mps is None else min_down_velocity_mps
        lo = min(floor, max_down_velocity_mps)
        speeds = np.linspace(lo, max_down_velocity_mps, settings.speeds)
        h1 = settings.tabulate_hold_s
        frame = pd.DataFrame({
            "down_velocity_mps": np.r_[speeds, speeds],
            "hold_s": np.r_[np.zeros(speeds.size), np.full(speeds.size, h1)],
            "vacuum_kpa": vacuum_kpa,
            **geometry.to_dict(),
        })
        out = predictor.predict(frame)
        n = speeds.size
        curve = LoudnessCurve.from_outcome(speeds, out["on_velocity"].to_numpy(float)[:n],
                                           out["p_silent"].to_numpy(float)[:n], settings.silent_p)
        lead = out["lead_s"].to_numpy(float)[:n]
        hold = out["midi_hold_s"].to_numpy(float)
        slope = (hold[n:] - hold[:n]) / h1
        slope = np.where(np.isfinite(slope) & (slope > 0.2) & (slope < 3.0), slope, FALLBACK_HOLD_SLOPE)
        busy = geometry.durations_s(speeds) + settings.recovery_s
        return cls(float(vacuum_kpa), geometry, settings, speeds, curve.velocity, _filled(lead),
                   _filled(hold[:n]), slope, busy)

    @property
    def curve(self) -> LoudnessCurve:
        """The loudness over down velocity, for the contract's inversion."""
        return LoudnessCurve(self.speeds_mps, self.velocity)

    @property
    def sounding(self) -> npt.NDArray[np.bool_]:
        return self.curve.sounding

    @property
    def sounds(self) -> bool:
        """At least two sounding speeds: a loudness range to invert."""
        return self.curve.sounds

    @property
    def velocity_range(self) -> tuple[float, float]:
        """(quietest, loudest) predicted on-velocity; NaNs when nothing sounds."""
        return self.curve.velocity_range

    def inverse(self, target: npt.ArrayLike) -> FloatArray:
        """Down velocity giving each target on-velocity (clipped to the reachable range)."""
        return self.curve.inverse(target)

    def fastest_within(self, target: npt.ArrayLike, tolerance: float) -> FloatArray:
        """The fastest down velocity predicted at most `tolerance` louder than each target."""
        return self.curve.fastest_within(target, tolerance)

    def predict_velocity(self, speed_mps: npt.ArrayLike) -> FloatArray:
        """Predicted on-velocity at down velocities (the monotone envelope)."""
        return self.curve.predict_velocity(speed_mps)

    def lead(self, speed_mps: npt.ArrayLike) -> FloatArray:
        return np.asarray(np.interp(_f(speed_mps), self.speeds_mps, self.lead_s), dtype=np.float64)

    def hold0(self, speed_mps: npt.ArrayLike) -> FloatArray:
        """Predicted MIDI hold at zero arm hold."""
        return np.asarray(np.interp(_f(speed_mps), self.speeds_mps, self.hold0_s), dtype=np.float64)

    def slope(self, speed_mps: npt.ArrayLike) -> FloatArray:
        """d(MIDI hold)/d(arm hold) at down velocities."""
        return np.asarray(np.interp(_f(speed_mps), self.speeds_mps, self.hold_slope), dtype=np.float64)

    def busy0(self, speed_mps: npt.ArrayLike) -> FloatArray:
        """Motion start → free for the next move, at zero hold (a hold adds itself)."""
        return np.asarray(np.interp(_f(speed_mps), self.speeds_mps, self.busy0_s), dtype=np.float64)

    def midi_hold(self, speed_mps: npt.ArrayLike, hold_s: npt.ArrayLike) -> FloatArray:
        """Predicted MIDI hold (note-on → note-off) for a down velocity and an arm hold."""
        return np.asarray(self.hold0(speed_mps) + self.slope(speed_mps) * _f(hold_s), dtype=np.float64)

    def arm_hold_for(self, speed_mps: npt.ArrayLike, midi_hold_s: npt.ArrayLike) -> FloatArray:
        """Arm hold so the predicted MIDI hold equals the wanted one (≥ 0, uncapped)."""
        wanted = (_f(midi_hold_s) - self.hold0(speed_mps)) / self.slope(speed_mps)
        return np.asarray(np.maximum(0.0, wanted), dtype=np.float64)

    def release_s(self, speed_mps: float, hold_s: float) -> float:
        """Predicted motion start → note-off: the key is back above its re-trigger depth then."""
        return float(self.lead(speed_mps)) + float(self.midi_hold(speed_mps, hold_s))

    def busy_s(self, speed_mps: float, hold_s: float) -> float:
        """Motion start → the next press or move may start: the press itself plus the recovery."""
        return busy_s(self.geometry, self.settings, speed_mps, hold_s)


def busy_s(geometry: StrokeGeometry, settings: PlaySettings, speed_mps: float, hold_s: float) -> float:
    """Motion start → the arm is back up and recovered: the press itself plus `recovery_s`."""
    return float(geometry.durations_s(np.array([speed_mps]), hold_s)[0]) + settings.recovery_s


def _f(values: npt.ArrayLike) -> FloatArray:
    return np.asarray(values, dtype=np.float64)


def _filled(values: FloatArray) -> FloatArray:
    """NaNs (silent speeds) filled from the nearest predicted value, so timing is defined."""
    ok = np.isfinite(values)
    if not ok.any():  # a level where nothing sounds: it will not be chosen
        return np.full(values.shape, np.nan)
    idx = np.arange(values.size)
    return np.asarray(np.interp(idx, idx[ok], values[ok]), dtype=np.float64)


def stroke_tables(predictor: StrokePredictor, settings: PlaySettings, rig: RigSpec,
                  geometry: StrokeGeometry | None = None, levels: Sequence[float] | None = None,
                  speed_ranges: dict[float, tuple[float, float]] | None = None) -> dict[float, StrokeTable]:
    """One table per allowed vacuum level (or `levels`) for a geometry (default: the fastest).

    `speed_ranges` per level limits the down velocities to where the model is trusted (a
    warm-up's mapped range), inside the envelope.
    """
    geometry = geometry or fastest_geometry(settings, rig)
    chosen = vacuum_levels(settings, rig) if levels is None else [float(p) for p in levels]
    cap = envelope_limits(settings, rig).get("down_velocity_mps", (0.0, 0.06))[1]
    out = {}
    for p in chosen:
        lo, hi = (speed_ranges or {}).get(p, (settings.min_down_velocity_mps, cap))
        out[p] = StrokeTable.build(predictor, p, geometry, settings, min(hi, cap), max(lo, 1e-4))
    return out
