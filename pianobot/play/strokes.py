"""A model's keystroke outcomes tabulated over down velocity, for fast per-note inverses.

For one stroke configuration (vacuum and a `StrokeGeometry`: hover distance, depth,
acceleration, up velocity) the planner asks the model once for on-velocity, silence, lead
(motion start → note-on) and MIDI hold at a grid of down velocities and two holds, then answers
every note by interpolation (vectorised: a 20,000-note song costs a few array operations). The
loudness curve is made monotone (running maximum over sounding speeds) so the inverse is
single-valued and picks the slowest speed that reaches a loudness.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.analysis.predictors import StrokePredictor
from pianobot.physics.trajectory import Press, contact_time_s, press_duration_s
from pianobot.plan import Trial
from pianobot.play.settings import PlaySettings

FloatArray = npt.NDArray[np.float64]

# The contact-speed move starts this much above the height where it would just reach its speed.
GAP_MARGIN = 1.25
# A fast approach shorter than this is not worth a second moveL (the controller's round trip).
MIN_APPROACH_M = 1e-3
# When the model's hold does not respond to the commanded hold (a learned model trained at one
# hold), holding the arm down longer keeps the key down just as much longer.
FALLBACK_HOLD_SLOPE = 1.0


@dataclass(frozen=True)
class StrokeGeometry:
    """The part of a press fixed for a song: hover, depth, acceleration, up velocity, approach.

    Per note only the down velocity (loudness) and the hold (length) change. The arm waits
    `distance_m` above the key (the hover). A slow stroke does not crawl all of that way: a fast
    approach (`approach_velocity_mps`, `approach_acceleration_mps2`) takes the arm down to just
    above the key, and the contact-speed move starts there — at the lowest height from which the
    arm reaches its commanded speed before contact (v²/2a, with a margin), and never below
    `clearance_m` (a stopped arm's finger must stay off the key). So every note has its own
    hover for the contact-speed move, and the arm meets the key at the commanded speed either
    way. The approach is used only where it makes the way to the key shorter; the stroke is a
    function of the down velocity alone, so the warm-up plays exactly the strokes the song uses.
    """

    distance_m: float
    depth_m: float
    acceleration_mps2: float
    up_velocity_mps: float
    approach_velocity_mps: float = 0.0  # 0: no fast approach
    approach_acceleration_mps2: float = 1.0
    clearance_m: float = 0.005

    def contact_gap_m(self, down_velocity_mps: float) -> float:
        """Height above the key where the contact-speed move starts (the note's own hover)."""
        v = float(down_velocity_mps)
        return min(self.distance_m, max(self.clearance_m, GAP_MARGIN * v * v / (2.0 * self.acceleration_mps2)))

    def press(self, down_velocity_mps: float, hold_s: float) -> Press:
        """The press of one note with this geometry (two-segment where that is faster)."""
        plain = Press(self.distance_m, self.depth_m, float(down_velocity_mps), self.up_velocity_mps,
                      self.acceleration_mps2, float(hold_s))
        approach = self.distance_m - self.contact_gap_m(down_velocity_mps)
        if self.approach_velocity_mps <= 0.0 or approach < MIN_APPROACH_M:
            return plain
        fast = replace(plain, approach_m=approach, travel_velocity_mps=self.approach_velocity_mps,
                       travel_acceleration_mps2=self.approach_acceleration_mps2)
        return fast if contact_time_s(fast) < contact_time_s(plain) else plain

    def durations_s(self, down_velocity_mps: npt.ArrayLike, hold_s: npt.ArrayLike = 0.0) -> FloatArray:
        """Motion start → arm back up, for many down velocities and holds (exact moveL timing)."""
        v, h = np.broadcast_arrays(np.asarray(down_velocity_mps, dtype=np.float64),
                                   np.asarray(hold_s, dtype=np.float64))
        out = [press_duration_s(self.press(float(a), float(b))) for a, b in zip(v.ravel(), h.ravel(), strict=True)]
        return np.asarray(out, dtype=np.float64).reshape(v.shape)

    def to_dict(self) -> dict[str, float]:
        """The press parameters (the columns a predictor reads)."""
        return {"distance_m": self.distance_m, "depth_m": self.depth_m,
                "acceleration_mps2": self.acceleration_mps2, "up_velocity_mps": self.up_velocity_mps}

    def describe(self) -> dict[str, float]:
        """Everything, for run.json and the JSON output."""
        return {**self.to_dict(), "approach_velocity_mps": self.approach_velocity_mps,
                "approach_acceleration_mps2": self.approach_acceleration_mps2, "clearance_m": self.clearance_m}


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
        on = out["on_velocity"].to_numpy(float)[:n].copy()
        silent = out["p_silent"].to_numpy(float)[:n] >= settings.silent_p
        on[silent | ~np.isfinite(on)] = np.nan
        lead = out["lead_s"].to_numpy(float)[:n]
        hold = out["midi_hold_s"].to_numpy(float)
        slope = (hold[n:] - hold[:n]) / h1
        slope = np.where(np.isfinite(slope) & (slope > 0.2) & (slope < 3.0), slope, FALLBACK_HOLD_SLOPE)
        busy = geometry.durations_s(speeds) + settings.recovery_s
        return cls(float(vacuum_kpa), geometry, settings, speeds, _monotone(on), _filled(lead),
                   _filled(hold[:n]), slope, busy)

    @property
    def sounding(self) -> npt.NDArray[np.bool_]:
        return np.isfinite(self.velocity)

    @property
    def sounds(self) -> bool:
        """At least two sounding speeds: a loudness range to invert."""
        return int(self.sounding.sum()) >= 2

    @property
    def velocity_range(self) -> tuple[float, float]:
        """(quietest, loudest) predicted on-velocity; NaNs when nothing sounds."""
        v = self.velocity[self.sounding]
        return (float(v[0]), float(v[-1])) if v.size else (float("nan"), float("nan"))

    def inverse(self, target: npt.ArrayLike) -> FloatArray:
        """Down velocity giving each target on-velocity (clipped to the reachable range)."""
        t = np.asarray(target, dtype=np.float64)
        ok = self.sounding
        if ok.sum() < 2:
            return np.full(t.shape, np.nan)
        v, s = self.velocity[ok], self.speeds_mps[ok]
        keep = np.r_[True, np.diff(v) > 1e-9]
        return np.asarray(np.interp(t, v[keep], s[keep]), dtype=np.float64)

    def fastest_within(self, target: npt.ArrayLike, tolerance: float) -> FloatArray:
        """The fastest down velocity predicted at most `tolerance` louder than each target.

        Louder is faster here: the loudness curve rises with speed. A target above the
        loudest stroke gets the fastest speed that still sounds loudest.
        """
        t = np.asarray(target, dtype=np.float64)
        ok = self.sounding
        if ok.sum() < 2:
            return np.full(t.shape, np.nan)
        v, s = self.velocity[ok], self.speeds_mps[ok]
        # The last speed reaching each loudness: np.interp over the reversed flat stretches.
        keep = np.r_[np.diff(v) > 1e-9, True]
        return np.asarray(np.interp(t + tolerance, v[keep], s[keep]), dtype=np.float64)

    def predict_velocity(self, speed_mps: npt.ArrayLike) -> FloatArray:
        """Predicted on-velocity at down velocities (the monotone envelope)."""
        ok = self.sounding
        return np.asarray(np.interp(_f(speed_mps), self.speeds_mps[ok], self.velocity[ok]), dtype=np.float64)

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


def stroke_trial(trial_id: str, index: int, pitch: int, vacuum_kpa: float, press: Press) -> Trial:
    """A planned keystroke (repeat 0) for the rig and the store, carrying the press's fast moves."""
    return Trial(trial_id, index, 0, int(pitch), float(vacuum_kpa), press.down_velocity_mps, press.up_velocity_mps,
                 press.acceleration_mps2, press.depth_m, press.distance_m, press.hold_s, 0.0,
                 approach_m=press.approach_m, retract_m=press.retract_m,
                 travel_velocity_mps=press.travel_velocity_mps, travel_acceleration_mps2=press.travel_acceleration_mps2)


def busy_s(geometry: StrokeGeometry, settings: PlaySettings, speed_mps: float, hold_s: float) -> float:
    """Motion start → the arm is back up and recovered: the press itself plus `recovery_s`."""
    return float(geometry.durations_s(np.array([speed_mps]), hold_s)[0]) + settings.recovery_s


def _f(values: npt.ArrayLike) -> FloatArray:
    return np.asarray(values, dtype=np.float64)


def _monotone(velocity: FloatArray) -> FloatArray:
    """Running maximum over the sounding part; NaN stays NaN (silent speeds)."""
    out = np.full(velocity.shape, np.nan)
    ok = np.isfinite(velocity)
    if ok.any():
        out[ok] = np.maximum.accumulate(velocity[ok])
    return out


def _filled(values: FloatArray) -> FloatArray:
    """NaNs (silent speeds) filled from the nearest predicted value, so timing is defined."""
    ok = np.isfinite(values)
    if not ok.any():  # a level where nothing sounds: it will not be chosen
        return np.full(values.shape, np.nan)
    idx = np.arange(values.size)
    return np.asarray(np.interp(idx, idx[ok], values[ok]), dtype=np.float64)
