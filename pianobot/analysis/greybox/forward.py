"""The measured-arm drive of the forward model: the physical keystroke, driven by the arm trace.

A keystroke does not start in contact. The fingertip starts `distance_m` above the key and hangs
from the arm on (k0, c0) while it approaches; the finger-key coupling (k1, c1) acts only from the
instant the gap closes (x1 − x2 ≥ distance_m); from then on the study's bilateral linear coupling
holds. Driving the study's in-contact state space with the arm trace from t = 0 instead would
push the key down from the first millimetre of the approach, and a fit would bend every
parameter to explain 5 cm of key travel that never happened.

Where the model applies: from rest, through the approach and the press, until the fingertip
leaves the key. The study's coupling is a bilateral spring: once engaged it never lets go, so on
the way up it pulls the key above its rest position and stretches the finger between key and
arm. A real finger lets go of the key (and a real key rests on its stop), so the model says
nothing true after lift-off; `model_window` ends each keystroke there (measured: after the key's
deepest point, when the fingertip-key gap has reopened by `LIFT_OFF_M` beyond the gap at which
the key started to move, or the key is back at rest; for a key that never moved, as one dry
friction holds down, after the finger's deepest compression, once the gap has reopened by
`LIFT_OFF_M` beyond the gap at which the fingertip closed it), and outputs are NaN after it.

A model with unilateral `contact` does describe what follows: the key returns on its own while
the finger hangs from the arm, and a pad that sticks (`adhesion`) pulls the key above rest until
it lets go, ringing. `MeasuredArm.of(batch, window="release")` models each keystroke further,
until the arm is back where it started plus `RELEASE_SETTLE_S` (`release_window`); discovery judges
those two effects on it (`lifts_off` says whether a keystroke's finger left the key at all).

`pianobot.physics.simulate.simulate_arm` integrates exactly this (the `KeystrokeModel` without
effects is the study's model with its free approach), thousands of keystrokes per second, which
is fast enough to sit inside `least_squares`. What this module adds is the sampling: each
keystroke's frames have their own clock phase (`KeystrokeBatch.t_offset_s`), and since the
system is time-invariant and at rest before the arm moves, row i is simulated with its input
advanced by its offset, so the simulator's output grid falls on that row's frames exactly. The
input is resampled for this once, finely enough (≤ 0.5 ms and ≤ half the input's own period)
that the piecewise-linear arm trace the simulator interpolates is unchanged.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.analysis.greybox.prediction import (
    SIM_STEP_S,
    TYPICAL_COMPRESSION_M,
    Prediction,
    integration_step,
    length_groups,
)
from pianobot.analysis.greybox.stages import KEY_MOTION_THRESHOLD_M, fill_gaps
from pianobot.physics.effects import Effects
from pianobot.physics.lanes import block_costs
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.msd import MSDParams
from pianobot.physics.simulate import effect_vector, internal_step_s, simulate_arm

FloatArray = npt.NDArray[np.float64]

#: Largest spacing of the resampled input.
INPUT_STEP_S = 5e-4
#: The fingertip has left the key once the fingertip-key gap has reopened by this much (well
#: above mocap noise, well below a finger's compression in a press).
LIFT_OFF_M = 5e-4
#: A fingertip has clearly left the key once the gap has reopened by this much (`lifts_off`).
CLEAR_OF_KEY_M = 1e-3
#: The release window runs this long after the arm is back at its start (ringing after a snap).
RELEASE_SETTLE_S = 0.15
#: The arm is back at its start within this distance of its lowest point before the press.
ARM_BACK_M = 2e-4

Window = Literal["press", "release"]


@dataclass(frozen=True, eq=False)
class MeasuredArm:
    """Parameter-independent preparation of a batch's simulation (build with `of`).

    Rows that repeat a keystroke (a bootstrap draw) are simulated once: `batch` holds the
    distinct keystrokes and `rows` maps the caller's rows onto them.
    """

    batch: KeystrokeBatch
    t_sim_s: FloatArray  # (M,) uniform simulation input grid, from rest
    lead: int  # output samples simulated before batch.t_s[0]
    lo: npt.NDArray[np.intp]  # (n, M) input-grid interval of each shifted sample
    frac: FloatArray  # (n, M) position inside it
    arm_sim_m: FloatArray  # (n, M) the batch's shifted input (parameter-independent, kept)
    last: npt.NDArray[np.intp]  # (n,) each row's last modelled sample (measured, before lift-off)
    rows: npt.NDArray[np.intp]  # (n_caller,) the distinct keystroke behind each caller's row
    observed: KeystrokeBatch  # the caller's batch (rows may repeat), which predictions are for
    compression_m: float = TYPICAL_COMPRESSION_M  # the finger's largest measured compression

    @classmethod
    def of(cls, batch: KeystrokeBatch, window: Window = "press") -> MeasuredArm:
        """The preparation for `batch`, each keystroke modelled until lift-off (`window="press"`)
        or through its release (`"release"`, for a model with unilateral contact)."""
        observed = batch
        _, first, rows = np.unique(np.asarray(batch.trial_id), return_index=True, return_inverse=True)
        if first.size < batch.n:
            batch = batch.subset(first)
        else:
            rows = np.arange(batch.n)
        dt = batch.dt_s
        if not dt > 0:
            raise ValueError("a keystroke batch needs at least two output samples to simulate.")
        t_in = batch.input_t_s
        # Start the simulation a whole number of output periods early, at or before the first
        # input sample, where the arm is at rest (the model starts at rest).
        lead = max(0, math.ceil((batch.t_s[0] - t_in[0]) / dt - 1e-9))
        t0 = float(batch.t_s[0] - lead * dt)
        dt_in = float(t_in[1] - t_in[0]) if t_in.size > 1 else dt
        per_out = max(1, math.ceil(dt / min(INPUT_STEP_S, 0.5 * dt_in) - 1e-9))
        step = dt / per_out
        t_end = float(batch.t_s[-1]) + dt
        t_sim = t0 + step * np.arange(int(math.ceil((t_end - t0) / step)) + 1, dtype=np.float64)
        # Row i's input advanced by its offset: its output samples land on its own frames.
        shifted = t_sim[None, :] + batch.t_offset_s[:, None]
        if t_in.size > 1:
            u = np.clip((shifted - t_in[0]) / dt_in, 0.0, t_in.size - 1.0)
            lo = np.minimum(u.astype(np.intp), t_in.size - 2)
            frac = u - lo
        else:
            lo = np.zeros(shifted.shape, dtype=np.intp)
            frac = np.zeros(shifted.shape)
        measured = np.isfinite(batch.x1_m) | np.isfinite(batch.x2_m)
        last = np.where(measured.any(axis=1), batch.t_s.size - 1 - np.argmax(measured[:, ::-1], axis=1), 0)
        last = np.minimum(last, model_window(batch) if window == "press" else release_window(batch))
        return cls(batch, t_sim, int(lead), lo, frac, _resample(batch.input_x0_m, lo, frac),
                   np.asarray(last, dtype=np.intp), np.asarray(rows, dtype=np.intp).ravel(), observed,
                   largest_compression_m(batch))

    def arm_m(self, input_x0_m: FloatArray | None = None) -> FloatArray:
        """The (shifted) arm input on the simulation grid; `input_x0_m` (the caller's rows)
        replaces the batch's (a repeated keystroke takes its first row's)."""
        if input_x0_m is None:
            return self.arm_sim_m
        first = np.zeros(self.batch.n, dtype=np.intp)
        first[self.rows[::-1]] = np.arange(self.rows.size)[::-1]
        return _resample(input_x0_m[first], self.lo, self.frac)

    def simulate(self, model: KeystrokeModel | MSDParams, input_x0_m: FloatArray | None = None,
                 *, states: bool = False) -> tuple[FloatArray, ...]:
        """Simulated fingertip x1 and key x2 (n, T) at each row's sample times, NaN after the
        row's last modelled sample (a keystroke is simulated only as long as it was measured);
        with `states` also the key speed and the finger's force on the key.

        Arm-side effects (`arm_lag`, `arm_acceleration`) do not apply: the arm is measured."""
        if isinstance(model, MSDParams):
            model = KeystrokeModel(msd=model, effects=Effects.none())
        step = integration_step(model, self.batch.vacuum_kpa, SIM_STEP_S, self.compression_m)
        return self._simulate([model], step, input_x0_m, states)[0]

    def simulate_many(self, models: Sequence[KeystrokeModel], *, states: bool = False) -> list[tuple[FloatArray, ...]]:
        """`simulate` for several models at once (a fit's Jacobian: one model per perturbed
        parameter). Models with the same effects and internal step run side by side: the
        rows of all of them are grouped by length together, so the simulator's wide blocks
        fill with keystrokes of one length instead of a few of every length in narrow ones.
        Each model's outputs are bit for bit those of `simulate` (a row never depends on its
        companions, nor on the block it runs in)."""
        batch = self.batch
        together: dict[tuple[tuple[float, bool], bytes], list[int]] = {}
        for j, model in enumerate(models):
            step_s, implicit = integration_step(model, batch.vacuum_kpa, SIM_STEP_S, self.compression_m)
            # Grouped by the step the simulator takes (a divisor of the frame period): a model
            # whose time scales a perturbation moved by a hair asks for another step but takes
            # the same one, and runs with the others (the same numbers as alone).
            step = (internal_step_s(batch.dt_s, step_s), implicit)
            together.setdefault((step, effect_vector(model.effects).tobytes()), []).append(j)
        results: list[tuple[FloatArray, ...]] = [() for _ in models]
        for (step, _), members in together.items():
            for j, out in zip(members, self._simulate([models[j] for j in members], step, None, states), strict=True):
                results[j] = out
        return results

    def _simulate(self, models: Sequence[KeystrokeModel], step: tuple[float, bool], input_x0_m: FloatArray | None,
                  states: bool) -> list[tuple[FloatArray, ...]]:
        """Each model's outputs (see `simulate`); the models share their effects and their step
        (length, implicit dampers: `integration_step`)."""
        step_s, implicit = step
        batch = self.batch
        arm = self.arm_m(input_x0_m)
        dt = batch.dt_s
        n = batch.n
        outs = [[np.full(batch.x1_m.shape, np.nan) for _ in range(4 if states else 2)] for _ in models]
        lengths = np.tile((self.lead + self.last + 1) * (dt / step_s), len(models))
        for pairs in length_groups(lengths, block_costs(models[0], trace=True, implicit=implicit)):
            which, rows = np.divmod(pairs, n)
            n_out = self.lead + int(self.last[rows].max()) + 1
            n_in = min(self.t_sim_s.size, int(math.ceil(n_out * dt / (self.t_sim_s[1] - self.t_sim_s[0]))) + 2)
            # One model alone takes the simulator's one-model path (the same numbers either way).
            model = models[0] if len(models) == 1 else [models[j] for j in which]
            with np.errstate(over="ignore", invalid="ignore"):  # trial parameters may be unstable
                sim = simulate_arm(self.t_sim_s[:n_in], arm[rows, :n_in], batch.vacuum_kpa[rows], model,
                                   distance_m=batch.distance_m[rows], key_start_m=batch.key_start_m[rows],
                                   out_dt_s=dt, duration_s=(n_out - 1) * dt, step_s=step_s,
                                   implicit_damping=implicit)
            # The key is measured from its own level before the keystroke (where it started).
            sims = (sim.x1_m, sim.x2_m - batch.key_start_m[rows, None], sim.v2_mps, sim.contact_force_n)
            for j in np.unique(which):
                mine = which == j
                for out, values in zip(outs[j], sims, strict=False):
                    out[rows[mine], : n_out - self.lead] = values[mine, self.lead :]
        after = self._after_last
        results = []
        for model_outs in outs:
            for out in model_outs:
                out[after] = np.nan
            results.append(tuple(model_outs) if self._rows_distinct else tuple(out[self.rows] for out in model_outs))
        return results

    @functools.cached_property
    def _after_last(self) -> npt.NDArray[np.bool_]:
        """(n, T): the samples after each distinct keystroke's last modelled one."""
        return np.asarray(np.arange(self.batch.t_s.size)[None, :] > self.last[:, None])

    @functools.cached_property
    def _rows_distinct(self) -> bool:
        """The caller's rows are the distinct keystrokes, in order (no bootstrap repeats)."""
        return bool(np.array_equal(self.rows, np.arange(self.batch.n)))

    def predict(self, model: KeystrokeModel, drive: dict[str, float] | None = None) -> Prediction:
        """The model's trajectories (and key states) at the batch's frames."""
        x1, x2, v2, force = self.simulate(model, states=True)
        return Prediction.trajectories(x1, x2, v2, force)

    def predict_many(self, models: Sequence[KeystrokeModel],
                     drives: Sequence[dict[str, float]] | None = None) -> list[Prediction]:
        """`predict` for several models at once (`simulate_many`): the same predictions."""
        return [Prediction.trajectories(*out) for out in self.simulate_many(models, states=True)]


#: The least compression a stiffening finger is judged at (a finger barely pressed).
MIN_COMPRESSION_M = 1e-3


def largest_compression_m(batch: KeystrokeBatch) -> float:
    """The finger's largest measured compression (fingertip below the key surface) before
    lift-off, at least `MIN_COMPRESSION_M`; `TYPICAL_COMPRESSION_M` without a fingertip trace."""
    if not batch.has_motion or batch.n == 0:
        return TYPICAL_COMPRESSION_M
    inside = np.arange(batch.t_s.size)[None, :] <= model_window(batch)[:, None]
    pen = batch.x1_m - batch.x2_m - batch.start_gap_m[:, None]
    pen = pen[inside & np.isfinite(pen)]
    return max(float(pen.max()), MIN_COMPRESSION_M) if pen.size else TYPICAL_COMPRESSION_M


#: The least body deflection a yielding finger is judged at (a body barely loaded).
MIN_DEFLECTION_M = 1e-3


def largest_deflection_m(batch: KeystrokeBatch) -> float | None:
    """The finger body's largest measured deflection (arm minus fingertip) before lift-off, at
    least `MIN_DEFLECTION_M`; None without a fingertip trace (MIDI only: never seen)."""
    if not batch.has_motion or batch.n == 0:
        return None
    inside = np.arange(batch.t_s.size)[None, :] <= model_window(batch)[:, None]
    body = np.abs(batch.x0_m - batch.x1_m)
    body = body[inside & np.isfinite(body)]
    return max(float(body.max()), MIN_DEFLECTION_M) if body.size else None


def model_window(batch: KeystrokeBatch) -> npt.NDArray[np.intp]:
    """Per keystroke, the last output sample the model describes: before the fingertip lifts
    off the key (see the module docstring); the whole trace when the fingertip never reached
    the key or never left it."""
    out = np.full(batch.n, batch.t_s.size - 1, dtype=np.intp)
    for i in range(batch.n):
        press = _press(batch, i)
        if press is None:
            continue
        x2, gap, touch, peak, moved = press
        after = np.arange(x2.size) > peak
        back = (x2 < KEY_MOTION_THRESHOLD_M) if moved else np.zeros(x2.size, dtype=bool)
        off = np.flatnonzero(after & ((gap < gap[touch] - LIFT_OFF_M) | back))
        if off.size:
            out[i] = int(off[0]) - 1
    return out


def _press(batch: KeystrokeBatch, i: int) -> tuple[FloatArray, FloatArray, int, int, bool] | None:
    """Keystroke i's key travel and fingertip-key gap (gaps filled), the sample where the
    finger took hold of the key and the deepest one after that, and whether the key moved.

    Where the key moved, the finger took hold where it started to move, and the press was
    deepest at its deepest point. A key that never moved (held down by dry friction, or a press
    too light to move it) was touched where the fingertip closed its starting gap, and pressed
    deepest where the finger was most compressed: a fingertip that then rises clear of a key
    held down has let go of it, which the study's bilateral coupling cannot do. None when the
    fingertip was not measured or never reached the key."""
    t = batch.row_times_s(i)
    if not np.isfinite(batch.x1_m[i]).any():
        return None
    x2 = fill_gaps(t, batch.x2_m[i])
    gap = fill_gaps(t, batch.x1_m[i]) - x2
    moved = np.flatnonzero(x2 > KEY_MOTION_THRESHOLD_M)
    if moved.size:
        touch = int(moved[0])
        return x2, gap, touch, touch + int(np.nanargmax(x2[touch:])), True
    held = np.flatnonzero(gap >= batch.start_gap_m[i])
    if held.size == 0:
        return None
    touch = int(held[0])
    return x2, gap, touch, touch + int(np.nanargmax(gap[touch:])), False


def release_window(batch: KeystrokeBatch) -> npt.NDArray[np.intp]:
    """Per keystroke, the last sample of its release: `RELEASE_SETTLE_S` after the arm is back within
    `ARM_BACK_M` of where it started (the whole trace when it never gets back, or without an arm
    marker)."""
    out = np.full(batch.n, batch.t_s.size - 1, dtype=np.intp)
    settle = int(round(RELEASE_SETTLE_S / batch.dt_s)) if batch.dt_s > 0 else 0
    for i in range(batch.n):
        if not np.isfinite(batch.x0_m[i]).any():
            continue
        x0 = fill_gaps(batch.row_times_s(i), batch.x0_m[i])
        top = int(np.nanargmax(x0))
        back = np.flatnonzero((np.arange(x0.size) > top) & (x0 < np.nanmin(x0[: top + 1]) + ARM_BACK_M))
        if back.size:
            out[i] = min(x0.size - 1, int(back[0]) + settle)
    return out


def lifts_off(batch: KeystrokeBatch) -> npt.NDArray[np.bool_]:
    """Per keystroke: after the key's deepest point, did the fingertip-key gap reopen by
    `CLEAR_OF_KEY_M` beyond the gap at which the key started to move (the finger left the key)?"""
    out = np.zeros(batch.n, dtype=bool)
    for i in range(batch.n):
        press = _press(batch, i)
        if press is not None:
            _, gap, touch, peak, _ = press
            out[i] = bool(np.nanmin(gap[peak:]) < gap[touch] - CLEAR_OF_KEY_M)
    return out


def _resample(x: FloatArray, lo: npt.NDArray[np.intp], frac: FloatArray) -> FloatArray:
    """Rows of x (n, T_in) linearly interpolated at fractional indices lo + frac (n, M)."""
    if x.shape[1] == 1:
        return np.repeat(x, lo.shape[1], axis=1)
    a = np.take_along_axis(x, lo, axis=1)
    b = np.take_along_axis(x, lo + 1, axis=1)
    return np.asarray(a + frac * (b - a), dtype=np.float64)


def simulate_batch(batch: KeystrokeBatch, model: KeystrokeModel | MSDParams) -> tuple[FloatArray, FloatArray]:
    """Simulated x1, x2 (n, T) of the keystroke model driven by the batch's arm traces."""
    x1, x2 = MeasuredArm.of(batch).simulate(model)
    return x1, x2
