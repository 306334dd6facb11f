"""The interface `play` uses to choose strokes: control parameters in, MIDI outcome out.

A `StrokePredictor` maps press parameters (the parameter table's `PREDICTOR_INPUTS`: vacuum and
the arm's motion) to the expected MIDI outcome: on-velocity, probability of a silent keystroke,
the lead time from motion start to note-on and the MIDI hold time. Its `inverse` answers the
question `play` asks per note: "which down velocity gives on-velocity v here?".

Implementations: `PhysicsPredictor` (simulates the physical model over a grid of presses and
interpolates; `PhysicsPredictor.published()` is the default when no model file is given) and the
learned predictors written by `pianobot fit` (`pianobot.analysis.learn`). `load_predictor(path)`
opens either kind by looking at the file's schema tag.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.errors import InputError
from pianobot.physics.model import MODEL_SCHEMA, KeystrokeModel, load_model
from pianobot.physics.piano import PianoParams, key_events
from pianobot.physics.simulate import simulate_presses
from pianobot.plan.trial import press_from
from pianobot.spec.parameters import PREDICTOR_INPUTS, input_default, missing_value

FloatArray = npt.NDArray[np.float64]

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
    """Forward and inverse map between press parameters and the MIDI outcome of one keystroke."""

    def predict(self, frame: pd.DataFrame) -> pd.DataFrame:
        """Outcome per row: `on_velocity` (1–127, NaN when silent is likely), `p_silent` (0–1),
        `lead_s` (motion start → note-on), `midi_hold_s` (note-on → note-off)."""
        ...

    def inverse(
        self,
        target_on_velocity: npt.ArrayLike,
        *,
        vacuum_kpa: float,
        acceleration_mps2: float,
        depth_m: float,
        distance_m: float,
    ) -> FloatArray:
        """Down velocity (m/s) that yields each target on-velocity; NaN where unreachable."""
        ...

    def velocity_range(
        self,
        *,
        vacuum_kpa: float,
        acceleration_mps2: float,
        depth_m: float,
        distance_m: float,
        max_down_velocity_mps: float,
    ) -> tuple[float, float]:
        """The lowest and highest sounding on-velocity reachable with down velocity ≤ the cap."""
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


def _envelope(speeds: FloatArray, velocity: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Finite, strictly increasing part of an on-velocity curve over increasing speeds.

    Noise (or a silent stretch) can make a predicted curve dip; a running maximum keeps the
    inverse single-valued and picks the slowest speed that reaches a loudness.
    """
    ok = np.isfinite(velocity)
    s, v = speeds[ok], np.maximum.accumulate(velocity[ok]) if ok.any() else velocity[ok]
    keep = np.r_[True, np.diff(v) > 1e-9] if v.size else np.zeros(0, bool)
    return s[keep], v[keep]


def speed_grid(lo_mps: float, hi_mps: float, n: int = 64) -> FloatArray:
    """Down speeds spanning [lo, hi] for tabulating a forward map."""
    lo = max(lo_mps, 1e-4)
    return np.linspace(lo, max(hi_mps, lo * 1.0001), n)


def _curve(predictor: StrokePredictor, speeds: FloatArray, **fixed: float) -> FloatArray:
    frame = pd.DataFrame({"down_velocity_mps": speeds, **{k: np.full(speeds.size, v) for k, v in fixed.items()}})
    out = predictor.predict(frame)
    velocity = out["on_velocity"].to_numpy(float).copy()
    velocity[out["p_silent"].to_numpy(float) >= 0.5] = np.nan  # a silent stroke has no loudness
    return velocity


def grid_inverse(
    predictor: StrokePredictor,
    target_on_velocity: npt.ArrayLike,
    lo_mps: float,
    hi_mps: float,
    **fixed: float,
) -> FloatArray:
    """Invert `predictor` in the down velocity by tabulating it on [lo, hi] (NaN when unreachable)."""
    target = np.asarray(target_on_velocity, dtype=np.float64)
    speeds = speed_grid(lo_mps, hi_mps)
    s, v = _envelope(speeds, _curve(predictor, speeds, **fixed))
    if s.size == 0:
        return np.full(target.shape, np.nan)
    if s.size == 1:
        return np.where(np.abs(target - v[0]) <= 0.5, s[0], np.nan)
    out = np.interp(target, v, s)
    return np.where((target >= v[0] - 1e-9) & (target <= v[-1] + 1e-9), out, np.nan)


def grid_velocity_range(
    predictor: StrokePredictor, lo_mps: float, hi_mps: float, **fixed: float
) -> tuple[float, float]:
    """(lowest, highest) sounding on-velocity over down speeds in [lo, hi]; NaNs if none sounds."""
    if hi_mps < lo_mps:
        return float("nan"), float("nan")
    velocity = _curve(predictor, speed_grid(lo_mps, hi_mps), **fixed)
    if not np.isfinite(velocity).any():
        return float("nan"), float("nan")
    return float(np.nanmin(velocity)), float(np.nanmax(velocity))


def _continuous_velocity(speed_mps: FloatArray, piano: PianoParams) -> FloatArray:
    """The piano's velocity curve without rounding (the inverse needs a continuous map)."""
    u = np.maximum(speed_mps, 0.0) / piano.full_scale_speed_mps
    g = u**piano.curve_exponent
    if piano.curve_saturation > 0.0:
        g = np.tanh(piano.curve_saturation * g) / np.tanh(piano.curve_saturation)
    return np.asarray(np.clip(127.0 * g, 1.0, 127.0), dtype=np.float64)


class PhysicsPredictor:
    """A `StrokePredictor` that simulates the physical model and reads the key out like the piano.

    `predict` simulates every row (batched, compiled integrator). `inverse` and
    `velocity_range` tabulate on-velocity over a geometric grid of down speeds for the given
    other parameters (cached) and interpolate on its increasing envelope.
    """

    #: Speeds tabulated for the inverse: from a crawl to the rigid finger's envelope limit.
    SPEEDS_MPS: FloatArray = np.geomspace(0.005, 0.5, 100)

    def __init__(self, model: KeystrokeModel) -> None:
        self.model = model
        self._tables: dict[tuple[float, ...], tuple[FloatArray, FloatArray]] = {}

    @classmethod
    def published(cls) -> PhysicsPredictor:
        """The study's model with the published parameters (the default for `play`)."""
        return cls(KeystrokeModel.study())

    def predict(self, frame: pd.DataFrame) -> pd.DataFrame:
        """Simulate each row's press and read out on-velocity, lead and hold (p_silent is 0 or 1)."""
        full = complete_inputs(frame)
        out = pd.DataFrame(index=frame.index, columns=list(OUTPUT_COLUMNS), dtype=float)
        if full.empty:
            return out
        presses = [press_from(dict(zip(full.columns, row, strict=True))) for row in full.to_numpy(float)]
        vacuum = full["vacuum_kpa"].to_numpy(float)
        piano = self.model.readout_params()
        values = np.full((len(presses), 4), np.nan)
        # Keystrokes in one batch share the longest one's duration: simulate slow presses
        # separately from fast ones so a crawl does not make every stroke expensive.
        order = np.argsort(full["down_velocity_mps"].to_numpy(float))
        for chunk in np.array_split(order, max(1, int(np.ceil(order.size / 16)))):
            sim = simulate_presses([presses[i] for i in chunk], vacuum[chunk], self.model)
            for row, i in enumerate(chunk):
                values[i] = self._readout(sim.t_s, sim.x2_m[row], piano)
        out.loc[:, list(OUTPUT_COLUMNS)] = values
        return out

    @staticmethod
    def _readout(t_s: FloatArray, x2_m: FloatArray, piano: PianoParams) -> list[float]:
        """[on_velocity, p_silent, lead_s, midi_hold_s] of one simulated key trace."""
        events, speed = key_events(t_s, x2_m, piano)
        ons = [e for e in events if e.type == "note_on"]
        if not ons:
            return [np.nan, 1.0, np.nan, np.nan]
        offs = [e for e in events if e.type == "note_off" and e.t_s >= ons[0].t_s]
        return [
            float(_continuous_velocity(np.array([speed]), piano)[0]),
            0.0,
            ons[0].t_s,
            offs[0].t_s - ons[0].t_s if offs else np.nan,
        ]

    def _table(self, **fixed: float) -> tuple[FloatArray, FloatArray]:
        key = tuple(round(fixed[k], 9) for k in sorted(fixed))
        if key not in self._tables:
            speeds = self.SPEEDS_MPS
            self._tables[key] = (speeds, _curve(self, speeds, **fixed))
        return self._tables[key]

    def inverse(self, target_on_velocity: npt.ArrayLike, *, vacuum_kpa: float,
                acceleration_mps2: float, depth_m: float, distance_m: float) -> FloatArray:
        """Slowest down velocity reaching each target on-velocity (NaN where unreachable)."""
        target = np.asarray(target_on_velocity, dtype=np.float64)
        speeds, velocity = self._table(vacuum_kpa=vacuum_kpa, acceleration_mps2=acceleration_mps2,
                                       depth_m=depth_m, distance_m=distance_m)
        s, v = _envelope(speeds, velocity)
        if s.size < 2:
            return np.full(target.shape, np.nan)
        out = np.interp(target, v, s)
        return np.where((target >= v[0]) & (target <= v[-1]), out, np.nan)

    def velocity_range(self, *, vacuum_kpa: float, acceleration_mps2: float, depth_m: float,
                       distance_m: float, max_down_velocity_mps: float) -> tuple[float, float]:
        """Sounding on-velocities reachable with down velocity ≤ the cap."""
        speeds, velocity = self._table(vacuum_kpa=vacuum_kpa, acceleration_mps2=acceleration_mps2,
                                       depth_m=depth_m, distance_m=distance_m)
        v = velocity[speeds <= max_down_velocity_mps]
        if not np.isfinite(v).any():
            return float("nan"), float("nan")
        return float(np.nanmin(v)), float(np.nanmax(v))


def load_predictor(path: str | Path) -> StrokePredictor:
    """Open a predictor file: a physics model (`pianobot.model/1`) or a learned one
    (`pianobot.predictor/1`, written by `pianobot fit`).

    Raises:
        InputError: missing file, not JSON, or another schema.
    """
    source = Path(path)
    try:
        payload = json.loads(source.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError("predictor file not found", str(source)) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"not a JSON predictor or model file ({exc})", str(source)) from None
    schema = payload.get("schema") if isinstance(payload, dict) else None
    if schema == MODEL_SCHEMA:
        return PhysicsPredictor(load_model(source))
    if schema == "pianobot.predictor/1":
        # Imported here: learn builds on this module's protocol and helpers.
        from pianobot.analysis.learn.training import load_learned

        return load_learned(source, payload)
    raise InputError(
        f"expected schema {MODEL_SCHEMA!r} or 'pianobot.predictor/1', got {schema!r}", str(source)
    )
