"""The contract `play` uses to choose strokes: control parameters in, MIDI outcome out, inverted.

A `StrokePredictor` maps press parameters (the parameter table's `PREDICTOR_INPUTS`: vacuum and
the arm's motion) to the expected MIDI outcome: on-velocity, probability of a silent keystroke,
the lead time from motion start to note-on and the MIDI hold time. `predict` is all a predictor
implements. The question `play` asks per note — "which down velocity gives on-velocity v
here?" — is answered once for every predictor by `LoudnessCurve`: the predicted on-velocity
tabulated over down velocities for one stroke configuration, made monotone, and interpolated.

Implementations: `PhysicsPredictor` (`learn.physical`: simulates the physical model;
`PhysicsPredictor.published()` is the default when no model file is given), the learned
predictors written by `pianobot fit` (`learn.training`) and play's warm-up model. Model files are
opened and written by `learn.files` (`load_predictor`, `save_predictor`), which sits above both
kinds, so neither imports the other.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.errors import InputError
from pianobot.spec.parameters import PREDICTOR_INPUTS, input_default, missing_value

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

#: Columns a predictor reads (missing ones take `DEFAULT_INPUTS`): the parameter table's
#: predictor inputs, in its order.
INPUT_COLUMNS: tuple[str, ...] = PREDICTOR_INPUTS
#: Columns every predictor returns, in this order.
OUTPUT_COLUMNS: tuple[str, ...] = ("on_velocity", "p_silent", "lead_s", "midi_hold_s")

#: Values used for inputs a caller leaves out: the parameter table's defaults (a sweep's trial
#: gets the same), its model stand-in where a sweep must say (depth); the up velocity follows
#: the down velocity and the down velocity must be given.
DEFAULT_INPUTS: dict[str, float] = {
    name: value for name in INPUT_COLUMNS if (value := input_default(name)) is not None
}


@runtime_checkable
class StrokePredictor(Protocol):
    """Forward map from press parameters to the MIDI outcome of one keystroke (invert it with
    `LoudnessCurve`)."""

    def predict(self, frame: pd.DataFrame) -> pd.DataFrame:
        """Outcome per row: `on_velocity` (1–127, NaN when silent is likely), `p_silent` (0–1),
        `lead_s` (motion start → note-on), `midi_hold_s` (note-on → note-off)."""
        ...


def complete_inputs(frame: pd.DataFrame) -> pd.DataFrame:
    """The input columns of `frame` with defaults filled in (up velocity defaults to down)."""
    if "down_velocity_mps" not in frame.columns:
        raise InputError("a predictor needs the column down_velocity_mps", "predict")
    out = pd.DataFrame(index=frame.index)
    given = {name: frame[name].astype(float) for name in INPUT_COLUMNS if name in frame.columns}
    for name in INPUT_COLUMNS:
        if name in given:
            out[name] = given[name]
        else:  # the followed column (up ← down), else the table's default
            missing = missing_value(name, given)
            out[name] = DEFAULT_INPUTS[name] if missing is None else missing
    return out


#: A prediction at least this likely silent has no loudness.
SILENT_P = 0.5


@dataclass(frozen=True)
class LoudnessCurve:
    """A predictor's on-velocity over increasing down velocities for one stroke configuration,
    made monotone: the one inversion of a `StrokePredictor`.

    The loudness is a running maximum over the sounding speeds (NaN where silent), so noise or
    a dip cannot make the inverse many-valued, and the inverse picks the slowest speed that
    reaches a loudness.
    """

    speeds_mps: FloatArray  # increasing
    velocity: FloatArray  # monotone envelope of the predicted on-velocity; NaN where silent

    @classmethod
    def from_outcome(cls, speeds_mps: npt.ArrayLike, on_velocity: npt.ArrayLike,
                     p_silent: npt.ArrayLike, silent_p: float = SILENT_P) -> LoudnessCurve:
        """The curve of predicted outcomes at `speeds_mps` (`p_silent >= silent_p`: silent)."""
        speeds = np.asarray(speeds_mps, dtype=np.float64)
        on = np.array(on_velocity, dtype=np.float64)
        on[(np.asarray(p_silent, dtype=np.float64) >= silent_p) | ~np.isfinite(on)] = np.nan
        velocity = np.full(on.shape, np.nan)
        ok = np.isfinite(on)
        if ok.any():
            velocity[ok] = np.maximum.accumulate(on[ok])
        return cls(speeds, velocity)

    @classmethod
    def tabulate(cls, predictor: StrokePredictor, speeds_mps: npt.ArrayLike, *,
                 silent_p: float = SILENT_P, **fixed: float) -> LoudnessCurve:
        """Ask `predictor` at `speeds_mps` with the other inputs `fixed` (missing: defaults)."""
        speeds = np.asarray(speeds_mps, dtype=np.float64)
        frame = pd.DataFrame({"down_velocity_mps": speeds, **{k: np.full(speeds.size, v) for k, v in fixed.items()}})
        out = predictor.predict(frame)
        return cls.from_outcome(speeds, out["on_velocity"].to_numpy(float), out["p_silent"].to_numpy(float),
                                silent_p)

    @property
    def sounding(self) -> BoolArray:
        """Where a stroke sounds."""
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

    def _rising(self, last: bool) -> tuple[FloatArray, FloatArray]:
        """Sounding (velocity, speed) with flat stretches cut to their first (or last) speed."""
        ok = self.sounding
        v, s = self.velocity[ok], self.speeds_mps[ok]
        rises = np.diff(v) > 1e-9
        keep = np.r_[rises, True] if last else np.r_[True, rises]
        return v[keep], s[keep]

    def inverse(self, target: npt.ArrayLike, *, strict: bool = False) -> FloatArray:
        """Slowest down velocity giving each target on-velocity.

        Targets outside the reachable range get its nearest end (what play does: the closest
        loudness there is); `strict=True` gives NaN there instead. NaN when fewer than two
        speeds sound.
        """
        t = np.asarray(target, dtype=np.float64)
        if not self.sounds:
            return np.full(t.shape, np.nan)
        v, s = self._rising(last=False)
        out = np.asarray(np.interp(t, v, s), dtype=np.float64)
        if strict:
            out = np.where((t >= v[0] - 1e-9) & (t <= v[-1] + 1e-9), out, np.nan)
        return out

    def fastest_within(self, target: npt.ArrayLike, tolerance: float) -> FloatArray:
        """The fastest down velocity predicted at most `tolerance` louder than each target.

        Louder is faster here: the loudness curve rises with speed. A target above the
        loudest stroke gets the fastest speed that still sounds loudest.
        """
        t = np.asarray(target, dtype=np.float64)
        if not self.sounds:
            return np.full(t.shape, np.nan)
        v, s = self._rising(last=True)  # the last speed reaching each loudness
        return np.asarray(np.interp(t + tolerance, v, s), dtype=np.float64)

    def predict_velocity(self, speed_mps: npt.ArrayLike) -> FloatArray:
        """Predicted on-velocity at down velocities (the monotone envelope)."""
        ok = self.sounding
        speeds = np.asarray(speed_mps, dtype=np.float64)
        return np.asarray(np.interp(speeds, self.speeds_mps[ok], self.velocity[ok]), dtype=np.float64)


def speed_grid(lo_mps: float, hi_mps: float, n: int = 64) -> FloatArray:
    """Down speeds spanning [lo, hi] for tabulating a forward map."""
    lo = max(lo_mps, 1e-4)
    return np.linspace(lo, max(hi_mps, lo * 1.0001), n)
