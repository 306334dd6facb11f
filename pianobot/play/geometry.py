"""The stroke geometry of a song: where the arm waits, how deep it presses, how it approaches.

`geometries(settings, rig)` lists the candidates the planner chooses from (hover × acceleration,
at the finger's depth and up speed, with the rig's fast approach), each checked against the
finger's safety envelope; `StrokeGeometry.press` turns a down velocity and a hold into the press
the arm executes (a two-segment press where that reaches the key sooner).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
import numpy.typing as npt

from pianobot.errors import InputError
from pianobot.physics.trajectory import Press
from pianobot.plan import Trial, move_durations_s
from pianobot.plan.trial import press_from, trial_from
from pianobot.play.settings import PlaySettings
from pianobot.spec import RigSpec

FloatArray = npt.NDArray[np.float64]

# The contact-speed move starts this much above the height where it would just reach its speed.
GAP_MARGIN = 1.25
# A fast approach shorter than this is not worth a second moveL (the controller's round trip).
MIN_APPROACH_M = 1e-3


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

    def contact_gap_m(self, down_velocity_mps: npt.ArrayLike) -> FloatArray:
        """Height above the key where the contact-speed move starts (each note's own hover)."""
        v = np.asarray(down_velocity_mps, dtype=np.float64)
        gap = np.maximum(self.clearance_m, GAP_MARGIN * v * v / (2.0 * self.acceleration_mps2))
        return np.asarray(np.minimum(self.distance_m, gap), dtype=np.float64)

    def approach_m(self, down_velocity_mps: npt.ArrayLike) -> FloatArray:
        """The fast approach of each down velocity's press (0: none; exact moveL timing).

        It is used where it is at least `MIN_APPROACH_M` long and the arm meets the key sooner
        than by crawling the whole hover at the contact speed.
        """
        v = np.asarray(down_velocity_mps, dtype=np.float64)
        approach = self.distance_m - self.contact_gap_m(v)
        if self.approach_velocity_mps <= 0.0:
            return np.zeros(v.shape)
        travel = self.distance_m + self.depth_m
        a = self.acceleration_mps2
        plain = _time_to(np.full(v.shape, self.distance_m), np.full(v.shape, travel), v, a)
        fast_move = move_durations_s(approach, np.full(v.shape, self.approach_velocity_mps),
                                     np.full(v.shape, self.approach_acceleration_mps2))
        fast = fast_move + _time_to(self.distance_m - approach, travel - approach, v, a)
        return np.asarray(np.where((approach >= MIN_APPROACH_M) & (fast < plain), approach, 0.0), dtype=np.float64)

    def press(self, down_velocity_mps: float, hold_s: float) -> Press:
        """The press of one note with this geometry (two-segment where that is faster)."""
        approach = float(self.approach_m(float(down_velocity_mps)))
        fast = {"approach_m": approach, "travel_velocity_mps": self.approach_velocity_mps,
                "travel_acceleration_mps2": self.approach_acceleration_mps2} if approach > 0 else {}
        return press_from({**self.to_dict(), "down_velocity_mps": down_velocity_mps, "hold_s": hold_s, **fast})

    def durations_s(self, down_velocity_mps: npt.ArrayLike, hold_s: npt.ArrayLike = 0.0) -> FloatArray:
        """Motion start → arm back up, for many down velocities and holds (exact moveL timing)."""
        v, h = np.broadcast_arrays(np.asarray(down_velocity_mps, dtype=np.float64),
                                   np.asarray(hold_s, dtype=np.float64))
        approach = self.approach_m(v)
        travel = self.distance_m + self.depth_m
        fast = move_durations_s(approach, np.full(v.shape, max(self.approach_velocity_mps, 1e-9)),
                                np.full(v.shape, self.approach_acceleration_mps2))
        down = move_durations_s(travel - approach, v, np.full(v.shape, self.acceleration_mps2))
        up = move_durations_s(np.full(v.shape, travel), np.full(v.shape, self.up_velocity_mps),
                              np.full(v.shape, self.acceleration_mps2))
        return np.asarray(np.where(approach > 0, fast, 0.0) + down + h + up, dtype=np.float64)

    def to_dict(self) -> dict[str, float]:
        """The press parameters (the columns a predictor reads)."""
        return {"distance_m": self.distance_m, "depth_m": self.depth_m,
                "acceleration_mps2": self.acceleration_mps2, "up_velocity_mps": self.up_velocity_mps}

    def describe(self) -> dict[str, float]:
        """Everything, for run.json and the JSON output."""
        return {**self.to_dict(), "approach_velocity_mps": self.approach_velocity_mps,
                "approach_acceleration_mps2": self.approach_acceleration_mps2, "clearance_m": self.clearance_m}


def _time_to(s_m: npt.ArrayLike, travel_m: npt.ArrayLike, v_mps: FloatArray, a_mps2: float) -> FloatArray:
    """Time a moveL from rest over `travel_m` (speed v, acceleration a) takes to cover `s_m`."""
    s, d = np.asarray(s_m, dtype=np.float64), np.asarray(travel_m, dtype=np.float64)
    peak = np.minimum(v_mps, np.sqrt(a_mps2 * d))
    ramp_m, ramp_s = peak * peak / (2.0 * a_mps2), peak / a_mps2
    total = 2.0 * ramp_s + (d - 2.0 * ramp_m) / peak
    out = np.where(s <= ramp_m, np.sqrt(2.0 * s / a_mps2),
                   np.where(s <= d - ramp_m, ramp_s + (s - ramp_m) / peak,
                            total - np.sqrt(2.0 * np.maximum(d - s, 0.0) / a_mps2)))
    return np.asarray(out, dtype=np.float64)


def stroke_trial(trial_id: str, index: int, pitch: int, vacuum_kpa: float, press: Press) -> Trial:
    """A planned keystroke (repeat 0) for the rig and the store, carrying the press's fast moves."""
    return trial_from(trial_id, index, 0, {"note": pitch, "vacuum_kpa": vacuum_kpa, **asdict(press)})


def geometries(settings: PlaySettings, rig: RigSpec) -> list[StrokeGeometry]:
    """The candidate stroke geometries; InputError if a setting leaves the finger's envelope."""
    env = rig.envelope_for(settings.finger)

    def checked(name: str, value: float) -> float:
        if name in env and not env[name].contains(value):
            raise InputError(
                f"{name} = {value:g} is outside the {settings.finger} finger's envelope "
                f"[{env[name].low:g}, {env[name].high:g}]", f"play settings: {name}",
            )
        return float(value)

    def top(name: str, fallback: float) -> float:
        return float(env[name].high) if name in env else fallback

    depth = checked("depth_m", settings.play_depth_m)
    up = checked("up_velocity_mps", settings.up_velocity_mps or top("up_velocity_mps", 0.7))
    accelerations = settings.accelerations_mps2 or (top("acceleration_mps2", 2.0),)
    fast = rig.approach  # the rig's two-segment press: speed of the fast move, clearance it keeps
    clearance = max(fast.clearance_m, settings.approach_clearance_m)
    return [
        StrokeGeometry(checked("distance_m", d), depth, checked("acceleration_mps2", a), up,
                       fast.velocity_mps if settings.fast_approach else 0.0, fast.acceleration_mps2, clearance)
        for a in accelerations for d in settings.hovers_m
    ]


def fastest_geometry(settings: PlaySettings, rig: RigSpec) -> StrokeGeometry:
    """The candidate with the shortest press cycle: shortest hover, highest acceleration."""
    return min(geometries(settings, rig), key=lambda g: (g.distance_m, -g.acceleration_mps2))


def envelope_limits(settings: PlaySettings, rig: RigSpec) -> dict[str, tuple[float, float]]:
    """The finger's envelope on this rig as (low, high) per parameter (geometry checked too)."""
    geometries(settings, rig)
    return {name: (lim.low, lim.high) for name, lim in rig.envelope_for(settings.finger).items()}


def vacuum_levels(settings: PlaySettings, rig: RigSpec) -> list[float]:
    """The settings' vacuum levels inside the finger's envelope; InputError if none is."""
    v_lo, v_hi = envelope_limits(settings, rig).get("vacuum_kpa", (-math.inf, math.inf))
    levels = [float(p) for p in settings.levels_kpa if v_lo - 1e-9 <= p <= v_hi + 1e-9]
    if not levels:
        raise InputError(
            f"no vacuum level of {list(settings.levels_kpa)} lies in the {settings.finger} finger's "
            f"envelope [{v_lo:g}, {v_hi:g}] kPa", "play settings: vacuum_levels_kpa",
        )
    return levels


