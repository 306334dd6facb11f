"""The commanded drive of the forward model: presses as the arm was told to make them.

For MIDI-only data (an old keystroke log) nothing measured the arm, so the model is driven by
each trial's commanded press: a UR moveL trapezoid when the model has `arm_acceleration`, the
study's constant-speed ramp otherwise, delayed by `arm_lag` when the model has it. What the data
do not record is a drive parameter the layout fits (`drive.acceleration_mps2`), never a silent
default; the trigger depth and the piano's velocity map are readout parameters of the model.

Outputs are the piano's MIDI outcome per keystroke, read from the simulated key trace at 1 ms
the way a two-sensor digital action reads it (`physics.piano`), but before rounding: the
on-velocity is the smooth function of key speed, and the crossings are interpolated between
samples, so a fit sees smooth functions of the parameters.

Only what the MIDI needs is simulated: each keystroke from just before its fingertip can reach
the key (started in flight, `physics.free_flight`: a slow press spends most of its time above
the key) until its arm has risen back past the depth it pressed plus a margin (the key is back
above its release depth by then); keystrokes are simulated in blocks of similar length.

The piano's readout (trigger and release depth, full-scale speed, velocity curve) does not act
on the keystroke, only on how it is read. A fit differentiates the readout's parameters too, so
the last few simulations are kept with the model they came from, minus its readout: a model
that differs from one of them only there is read again from the same key traces, not simulated
(the same numbers: the simulation's inputs are the same).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from pianobot.analysis.greybox._midi_kernel import key_crossings
from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.analysis.greybox.prediction import (
    SIM_STEP_S,
    Prediction,
    integration_step_s,
    length_groups,
)
from pianobot.physics.lanes import block_costs
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.piano import PianoParams, on_velocity_from_speed
from pianobot.physics.simulate import flight_starts, simulate_presses
from pianobot.physics.trajectory import Press, press_timing

FloatArray = npt.NDArray[np.float64]

OUT_DT_S = 1e-3
#: A group of keystrokes simulated together: rows, starts, key traces, valid samples.
Traces = tuple[npt.NDArray[np.intp], FloatArray, FloatArray, npt.NDArray[np.bool_]]
#: Simulations kept for a model that differs only in its readout (a fit's Jacobian perturbs each
#: parameter in turn from the same point; the readout's come after the model's own).
KEPT_SIMULATIONS = 4
#: Simulated past the arm's rise through the pressed depth: the key settles above release.
RISE_MARGIN_M = 5e-3
#: Simulated past that, so the key rises through its release depth and the note-off registers.
RELEASE_TAIL_S = 0.15


def _cut_s(press: Press, profile: str, lag_s: float) -> float:
    """How long keystroke `press` must be simulated for its MIDI outcome."""
    tm = press_timing(press, "trapezoid" if profile == "trapezoid" else "ramp")
    rise = min(press.depth_m + RISE_MARGIN_M, tm.up.distance_m)
    return float(tm.t_hold_end_s + tm.up.time_at_m(rise) + RELEASE_TAIL_S + lag_s)


def _cross_s(x2: FloatArray, valid: npt.NDArray[np.bool_], k: npt.NDArray[np.intp], level: float,
             dt_s: float) -> FloatArray:
    """Interpolated time of crossing `level` between samples k − 1 and k of each row (a sample
    outside the valid ones counts as −inf)."""
    rows = np.arange(x2.shape[0])
    k = np.maximum(k, 1)
    a = np.where(valid[rows, k - 1], x2[rows, k - 1], -np.inf)
    b = np.where(valid[rows, k], x2[rows, k], -np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(b != a, (level - a) / (b - a), 0.0)
    return np.asarray((k - 1 + np.clip(frac, 0.0, 1.0)) * dt_s, dtype=np.float64)


#: Width (MIDI units) of the smooth floor at velocity 1 (`velocity_floor`): within rounding.
VELOCITY_FLOOR_WIDTH = 0.25


def velocity_floor(velocity: FloatArray) -> FloatArray:
    """1 + w·log(1 + e^((v − 1)/w)): v above about 2, 1 far below, smooth (with a slope) between;
    at most w·log 2 ≈ 0.17 above max(v, 1)."""
    w = VELOCITY_FLOOR_WIDTH
    return 1.0 + w * np.logaddexp(0.0, (velocity - 1.0) / w)


def midi_outcomes(x2_m: FloatArray, valid: npt.NDArray[np.bool_], piano: PianoParams,
                  dt_s: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """(on-velocity before rounding and clipping, note-on time, hold, trigger margin) of key traces.

    The note sounds when the key reaches the lower sensor, with the velocity of the speed
    between the two sensors; it stops when the key rises back past the release depth. `valid`
    masks each row's simulated samples.
    """
    top, k_up, k_lo, sounded, k_off, released = key_crossings(
        np.ascontiguousarray(x2_m, dtype=np.float64), np.ascontiguousarray(valid, dtype=np.bool_),
        piano.upper_sensor_m, piano.lower_sensor_m, piano.release_m)
    margin = top - piano.lower_sensor_m
    t_up = _cross_s(x2_m, valid, k_up, piano.upper_sensor_m, dt_s)
    t_on = _cross_s(x2_m, valid, k_lo, piano.lower_sensor_m, dt_s)
    gap = piano.lower_sensor_m - piano.upper_sensor_m
    speed = gap / np.maximum(t_on - t_up, 1e-6)
    # Not clipped to the MIDI range: a fit needs the slope everywhere (measured velocities are
    # 1–127 anyway, and a model above them is simply that far off). Below, a sounded note is
    # never sent softer than 1: a smooth floor there, or the slowest keystrokes of a soft log
    # (the study's: a third of them at 1) read as a model error of up to one unit each.
    velocity = velocity_floor(on_velocity_from_speed(speed, piano, rounded=False, clipped=False))
    rows = np.arange(x2_m.shape[0])
    a, b = x2_m[rows, np.maximum(k_off - 1, 0)], x2_m[rows, k_off]
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.clip(np.where(a != b, (a - piano.release_m) / (a - b), 0.0), 0.0, 1.0)
    t_off = (k_off - 1 + frac) * dt_s
    hold = np.where(released, t_off - t_on, np.nan)
    nan = np.nan
    return (np.where(sounded, velocity, nan), np.where(sounded, t_on, nan), np.where(sounded, hold, nan),
            np.asarray(margin, dtype=np.float64))


@dataclass(frozen=True, eq=False)
class Commanded:
    """The commanded drive over a batch (see the module docstring)."""

    batch: KeystrokeBatch
    out_dt_s: float = OUT_DT_S
    # The presses of the last acceleration asked for: a fit varies the model far more often
    # than the drive's acceleration, and a Press is immutable.
    _last: list[Any] = field(default_factory=lambda: [None, None], init=False, repr=False, compare=False)
    # (model without its readout, acceleration) -> each group's rows, starts, key traces and
    # valid samples.
    _kept: list[tuple[Any, list[Traces]]] = field(
        default_factory=list, init=False, repr=False, compare=False)

    def presses(self, acceleration_mps2: float | None) -> list[Press]:
        """The batch's commanded presses (`acceleration_mps2` where none is recorded)."""
        key, presses = self._last
        if presses is None or key != acceleration_mps2:
            presses = [self.batch.press(i, acceleration_mps2) for i in range(self.batch.n)]
            self._last[:] = [acceleration_mps2, presses]
        return list(presses)

    @property
    def observed(self) -> KeystrokeBatch:
        """The batch the predictions are for."""
        return self.batch

    @property
    def needs_acceleration(self) -> bool:
        """True when some keystroke does not record its acceleration (a drive parameter)."""
        return bool(np.isnan(self.batch.acceleration_mps2).any())

    def key_traces(self, model: KeystrokeModel, accel: float | None) -> list[Traces]:
        """Each group's rows, their starts (s into the press), simulated key traces from there
        (NaN as 0) and valid samples; kept for a model that differs only in its readout (see
        the module docstring)."""
        key = (replace(model, effects=model.effects.without("velocity_curve"), piano=PianoParams()), accel)
        for i, (seen, traces) in enumerate(self._kept):
            if seen == key:
                self._kept.append(self._kept.pop(i))
                return traces
        batch = self.batch
        presses = self.presses(accel)
        lag = model.effects.value("arm_lag", "arm_lag_s", 0.0)
        cuts = np.array([_cut_s(p, model.arm_profile, lag) for p in presses])
        step_s = integration_step_s(model, batch.vacuum_kpa, SIM_STEP_S)
        # Each keystroke starts just before its fingertip can reach the key, in flight.
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            flight = flight_starts(presses, batch.vacuum_kpa, model, out_dt_s=self.out_dt_s, step_s=step_s)
        starts = flight.start_s
        spans = np.maximum(cuts - starts, 0.0)
        traces = []
        for rows in length_groups(spans / step_s, block_costs(model, trace=False)):
            duration = float(spans[rows].max())
            with np.errstate(over="ignore", invalid="ignore"):
                sim = simulate_presses([presses[i] for i in rows], batch.vacuum_kpa[rows], model,
                                       out_dt_s=self.out_dt_s, duration_s=duration, step_s=step_s,
                                       start=flight.take(rows))
            valid = sim.t_s[None, :] <= spans[rows][:, None]
            traces.append((rows, starts[rows], np.where(np.isfinite(sim.x2_m), sim.x2_m, 0.0), valid))
        self._kept.append((key, traces))
        del self._kept[: max(len(self._kept) - KEPT_SIMULATIONS, 0)]
        return traces

    def __getstate__(self) -> dict[str, Any]:
        """Pickled (for a worker) without the kept simulations: tens of MB of key traces."""
        state = dict(self.__dict__)
        state["_kept"] = []
        return state

    def predict(self, model: KeystrokeModel, drive: dict[str, float] | None = None) -> Prediction:
        """The model's MIDI outcome for every keystroke of the batch."""
        batch = self.batch
        accel = (drive or {}).get("acceleration_mps2")
        piano = model.readout_params()
        n = batch.n
        out = [np.full(n, np.nan) for _ in range(4)]
        for rows, starts, x2, valid in self.key_traces(model, accel):
            velocity, t_on, hold, margin = midi_outcomes(x2, valid, piano, self.out_dt_s)
            for target, values in zip(out, (velocity, t_on + starts, hold, margin), strict=True):
                target[rows] = values
        empty = np.zeros((n, batch.t_s.size))
        return Prediction(np.full_like(empty, np.nan), np.full_like(empty, np.nan), np.zeros((n, 0)),
                          np.zeros((n, 0)), *out)
