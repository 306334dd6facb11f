"""Fast batch simulation of keystrokes with any set of effects.

A keystroke runs from approach to rest: before contact the fingertip is a free mass-spring-
damper hanging from the arm (m1, k0, c0); once it touches the key (x1 − x2 ≥ distance_m) the
coupling k1, c1 acts on the key (m2, k2, c2). Without the `contact` effect the coupling is the
study's bilateral linear spring, engaged at first touch and never released (so it also pulls
the key back up with the finger); with `contact` it only pushes, and the finger and key
separate and re-touch. The other effects are described in `effects.py`.

Integration is a compiled fixed-step semi-implicit scheme (see `_kernel.py`) with an internal
step ≤ 0.2 ms, outputs taken every `out_dt_s`. Keystrokes of different length share one time
grid: each is simulated to the end of the longest (arm at rest at its start height after). A
keystroke's samples never depend on its companions: alone it has the first
`output_count(duration, out_dt_s)` of them, bit for bit; past its own horizon a row simply goes
on (the key keeps settling), so readers that look for "the end" should cut at that horizon.
"""

from __future__ import annotations

import functools
import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.physics import _kernel as K
from pianobot.physics import free_flight
from pianobot.physics.effects import Effects
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.msd import MSDParams
from pianobot.physics.trajectory import Press, press_timing

FloatArray = npt.NDArray[np.float64]

# Keystrokes per call for a caller that batches many (sorted by length): the kernel's SIMD
# block. More lanes per call only make more keystrokes wait for the longest of their batch and
# push its output out of cache (random sweep, 128-trial blocks: 118 µs per keystroke at 16
# lanes, 140 at 64; the same 3,840 presses sorted as a whole: 57 against 85-97).
BATCH_LANES = K.BLOCK
SMALL_LANES = K.SMALL_BLOCK  # a call with at most this many keystrokes runs the small kernel
LANE_BLOCKS = K.BLOCKS  # a call runs the smallest of these that holds its keystrokes
MAX_STEP_S = 2e-4  # impacts on the keybed (≈ 150 Hz) need at least ~30 steps per period
SETTLE_S = 0.3  # simulated after the arm is back up, so the key can come to rest


@dataclass(frozen=True)
class SimBatch:
    """Simulated keystrokes on one time grid: arrays of shape (n, T), time (T,)."""

    t_s: FloatArray
    x0_m: FloatArray
    x1_m: FloatArray
    x2_m: FloatArray
    v2_mps: FloatArray
    contact_force_n: FloatArray

    @property
    def n(self) -> int:
        return int(self.x2_m.shape[0])

    def to_pandas(self) -> pd.DataFrame:
        """Long form: one row per (keystroke, sample) with every signal as a column."""
        n, T = self.x2_m.shape
        return pd.DataFrame(
            {
                "keystroke": np.repeat(np.arange(n), T),
                "t_s": np.tile(self.t_s, n),
                "x0_m": self.x0_m.ravel(),
                "x1_m": self.x1_m.ravel(),
                "x2_m": self.x2_m.ravel(),
                "v2_mps": self.v2_mps.ravel(),
                "contact_force_n": self.contact_force_n.ravel(),
            }
        )


def drift_factor(block_key: str, drift_fraction: float) -> float:
    """Relative finger stiffness of a block: 1 + drift_fraction·u, u ∈ [−1, 1] from the key.

    Deterministic (a hash, not hidden state) so a resumed run sees the same drift.
    """
    digest = hashlib.sha256(block_key.encode("utf-8")).digest()
    u = int.from_bytes(digest[:8], "big") / float(2**64) * 2.0 - 1.0
    return 1.0 + drift_fraction * u


def effect_vector(effects: Effects) -> FloatArray:
    """The kernel's effect switches and values for a set of effects."""
    ep = np.zeros(K.N_EP)
    ep[K.E_CONTACT] = 1.0 if "contact" in effects else 0.0
    if "keybed" in effects:
        p = effects.params("keybed")
        ep[K.E_BED_ON] = 1.0 if p["bed_stiffness_npm"] > 0.0 else 0.0
        ep[K.E_BED_HC] = 1.0 if effects.form("keybed") == "hunt_crossley" else 0.0
        ep[K.E_BED_DEPTH] = p["bed_depth_m"]
        ep[K.E_BED_K] = p["bed_stiffness_npm"]
        ep[K.E_BED_C] = p["bed_damping_nspm"]
    ep[K.E_PRELOAD] = effects.value("key_preload", "preload_n", 0.0)
    ep[K.E_PRELOAD_W] = effects.value("key_preload", "preload_width_m", 0.0, form="smooth")
    if "key_friction" in effects:
        p = effects.params("key_friction")
        ep[K.E_FRIC_C] = p["friction_n"]
        if effects.form("key_friction") == "stribeck":
            ep[K.E_FRIC_S] = p["static_friction_n"]
            ep[K.E_FRIC_VS] = p["stribeck_velocity_mps"]
        ep[K.E_FRIC_ON] = 1.0 if max(ep[K.E_FRIC_C], ep[K.E_FRIC_S]) > 0.0 else 0.0
    if "finger_stiffening" in effects:
        form = effects.form("finger_stiffening")
        ep[K.E_STIFF_FORM] = {"cubic": K.STIFF_CUBIC, "exponential": K.STIFF_EXP, "power": K.STIFF_POWER}[form]
        ep[K.E_STIFF_BETA] = effects.params("finger_stiffening")["stiffening_per_m"]
        ep[K.E_STIFF_Q] = effects.value("finger_stiffening", "stiffening_exponent", 2.0)
    if "contact" in effects:  # adhesion acts only where the contact can open at all
        ep[K.E_ADHESION] = effects.value("adhesion", "pull_off_force_n", 0.0)
        ep[K.E_ADH_RANGE] = effects.value("adhesion", "adhesion_range_m", 0.0, form="cohesive")
    if "letoff" in effects:
        p = effects.params("letoff")
        ep[K.E_LETOFF_F] = p["letoff_force_n"]
        ep[K.E_LETOFF_X] = p["letoff_depth_m"]
        ep[K.E_LETOFF_W] = p["letoff_width_m"]
    if "finger_hysteresis" in effects:
        p = effects.params("finger_hysteresis")
        ep[K.E_HYST_SHARE] = p["yield_share"]
        ep[K.E_HYST_YIELD] = p["yield_m"]
        ep[K.E_HYST_SET] = p["yield_set"]
    if "arm_lag" in effects:
        form = effects.form("arm_lag")
        ep[K.E_LAG_FORM] = K.LAG_FIRST_ORDER if form == "first_order" else K.LAG_DELAY
        ep[K.E_LAG_S] = effects.params("arm_lag")["arm_lag_s"]
    return ep


def _model_columns(
    msd: MSDParams, effects: Effects, vacuum_kpa: FloatArray, block_keys: Sequence[str] | None
) -> FloatArray:
    """Per-keystroke physical parameters (drift applied to the finger's k0 and k1)."""
    n = vacuum_kpa.size
    kp = np.zeros((n, K.N_KP))
    drift = effects.value("stiffness_drift", "drift_fraction", 0.0)
    if block_keys is not None and len(block_keys) != n:
        raise ValueError(f"block_keys has {len(block_keys)} entries for {n} keystrokes.")
    cache: dict[tuple[float, str], tuple[float, ...]] = {}
    for j in range(n):
        key = "" if block_keys is None else str(block_keys[j])
        p = float(vacuum_kpa[j])
        row = cache.get((p, key))
        if row is None:
            lp = msd.at(p)
            scale = drift_factor(f"{key}|{p:g}", drift) if drift > 0.0 else 1.0
            row = (
                lp.m1_kg, lp.m2_kg, lp.k0_npm * scale, lp.c0_nspm,
                lp.k1_npm * scale, lp.c1_nspm, lp.k2_npm, lp.c2_nspm,
            )
            cache[(p, key)] = row
        kp[j, : K.DIST] = row
    return kp


def internal_step_s(out_dt_s: float, step_s: float) -> float:
    """The step a simulation asked for `step_s` at output period `out_dt_s` takes: the largest
    divisor of the output period not above `step_s`. Steps asked for that share it give the same
    numbers (a fit's perturbed models whose time scales moved by a hair run side by side)."""
    return _grid(out_dt_s, step_s)[0]


def _grid(out_dt_s: float, step_s: float) -> tuple[float, int]:
    """Internal step (a divisor of the output step, ≤ step_s ≤ MAX_STEP_S) and outputs per step."""
    if not out_dt_s > 0.0 or not step_s > 0.0:
        raise ValueError(f"out_dt_s and step_s should be > 0, got {out_dt_s} and {step_s}.")
    if step_s > MAX_STEP_S:
        raise ValueError(f"step_s should be <= {MAX_STEP_S} s for impacts, got {step_s}.")
    every = max(1, math.ceil(out_dt_s / step_s - 1e-9))
    return out_dt_s / every, every


_KEY_SIDE = (
    K.E_CONTACT, K.E_BED_ON, K.E_PRELOAD, K.E_FRIC_ON, K.E_STIFF_BETA, K.E_ADHESION, K.E_LETOFF_F,
    K.E_HYST_SHARE,  # the finger's body, not the key: but only the full step has it
)


def _is_linear(ep: FloatArray) -> bool:
    """True when no effect acts on the finger or key: the fast linear kernel applies."""
    return not any(ep[i] != 0.0 for i in _KEY_SIDE)


def runs_linear_kernel(effects: Effects) -> bool:
    """Whether a model with these effects is simulated by the fast linear kernel (no effect on
    the finger or key), whose steps cost differently (see `greybox.prediction.length_groups`)."""
    return _is_linear(effect_vector(effects))


def body_set_m(ep: FloatArray) -> float:
    """The permanent set of a yielding finger body that earlier presses yielded (0 for a fresh
    one): at zero force its slider has sprung back f·u_y, so the elastic share holds it at
    σ·f·u_y/(1 − σ) of deflection and the fingertip hangs that much higher."""
    share = float(ep[K.E_HYST_SHARE])
    return share * float(ep[K.E_HYST_SET]) * float(ep[K.E_HYST_YIELD]) / (1.0 - share) if share < 1.0 else 0.0


def kernel_family(ep: FloatArray) -> dict[int, Any]:
    """The compiled kernel family for these effects: a model pays only for what it has (a
    power-law finger, a yielding body, a smooth rest stop, a cohesive skin, implicit dampers),
    and a model without them runs exactly the code it ran before they existed. Implicit dampers
    (E_IMPLICIT, set by `_run`, not an effect) take the full step even without effects."""
    implicit = bool(ep[K.E_IMPLICIT] != 0.0)
    if _is_linear(ep) and not implicit:
        return K.integrate_linear
    power = bool(ep[K.E_STIFF_FORM] == K.STIFF_POWER)
    hysteresis = bool(ep[K.E_HYST_SHARE] > 0.0)
    smooth_stop = bool(ep[K.E_PRELOAD] > 0.0 and ep[K.E_PRELOAD_W] > 0.0)
    cohesive = bool(ep[K.E_ADHESION] > 0.0 and ep[K.E_ADH_RANGE] > 0.0)
    return K.integrate_full[(power, hysteresis, smooth_stop, cohesive, implicit)]


def output_count(duration_s: float, out_dt_s: float) -> int:
    """Samples of a simulation of `duration_s` (0, out_dt_s, ... up to duration_s inclusive).

    A keystroke alone has this many samples; in a longer batch its first this-many are the same.
    """
    return int(math.floor(duration_s / out_dt_s + 1e-9)) + 1


def _run(
    kp: FloatArray, ep: FloatArray, mode: int, trace_t: FloatArray, trace_x0: FloatArray,
    t_start: float, duration_s: float, out_dt_s: float, step_s: float, implicit_damping: bool = False,
) -> SimBatch:
    h, every = _grid(out_dt_s, step_s)
    if implicit_damping:
        ep = ep.copy()
        ep[K.E_IMPLICIT] = 1.0
    n_out = output_count(duration_s, out_dt_s)
    n_steps = (n_out - 1) * every
    n = kp.shape[0]
    outs = [np.empty((n, n_out)) for _ in range(5)]
    kernels = kernel_family(ep)
    if ep[K.E_HYST_SHARE] > 0.0:  # a yielding body's kernels
        kp = kp.copy()
        kp[:, K.DIST] += body_set_m(ep)  # the fingertip hangs that much higher above the key
    kernel = kernels[block_for(n)]
    kernel(kp, ep, mode, trace_t, trace_x0, t_start, h, n_steps, every, *outs)
    t = np.asarray(t_start + np.arange(n_out) * out_dt_s, dtype=np.float64)
    return SimBatch(t, *outs)


def block_for(n: int) -> int:
    """The compiled block a call of `n` keystrokes runs: the smallest that holds them (a few
    keystrokes should not pay for 16 SIMD lanes), `BATCH_LANES` beyond."""
    return next((b for b in K.BLOCKS if n <= b), K.BLOCK)


def _vacuum(vacuum_kpa: npt.ArrayLike, n: int) -> FloatArray:
    p = np.asarray(vacuum_kpa, dtype=np.float64)
    if p.ndim == 0:
        return np.full(n, float(p))
    if p.shape != (n,):
        raise ValueError(f"vacuum_kpa should be a scalar or have {n} entries, got shape {p.shape}.")
    return p


def press_columns(presses: Sequence[Press], profile: str) -> tuple[FloatArray, FloatArray]:
    """The kernel's arm columns (n, N_KP) for presses, and each press's duration (s)."""
    kind = "trapezoid" if profile == "trapezoid" else "ramp"
    kp = np.zeros((len(presses), K.N_KP))
    ends = np.zeros(len(presses))
    for j, press in enumerate(presses):
        kp[j], ends[j] = _press_row(press, kind)
    return kp, ends


@functools.lru_cache(maxsize=4096)
def _press_row(press: Press, profile: str) -> tuple[FloatArray, float]:
    """One press's arm columns and duration, kept: a fit simulates the same presses at every
    evaluation (a Press is immutable, so equal presses have equal columns)."""
    tm = press_timing(press, profile)
    row = np.zeros(K.N_KP)
    moves = ((K.D_A, tm.down), (K.U_A, tm.up), (K.F_A, tm.approach), (K.R_A, tm.retract))
    for cols, mv in moves:
        a = mv.acceleration_mps2 if math.isfinite(mv.acceleration_mps2) else 0.0
        row[cols : cols + 4] = (a, mv.t_accel_s, mv.t_cruise_s, mv.peak_velocity_mps)
    row[K.T_UP] = tm.t_hold_end_s
    row[K.T_DN] = tm.t_down_start_s
    row[K.T_RE] = tm.t_lifted_s
    row[K.DIST] = press.distance_m
    row.flags.writeable = False
    return row, tm.t_end_s


@dataclass(frozen=True)
class FlightStarts:
    """Where each press's simulation starts (s into its motion, on the output grid, before its
    fingertip can reach the key) and its fingertip's state there (columns U1S, V1S, A1S of the
    kernel: offset from the arm, half-step velocity, last acceleration). All zero: at rest."""

    start_s: FloatArray  # (n,)
    state: FloatArray  # (n, 3)
    out_dt_s: float
    step_s: float

    def take(self, rows: npt.ArrayLike) -> FlightStarts:
        """The starts of some of the presses (in that order)."""
        idx = np.asarray(rows, dtype=np.intp)
        return FlightStarts(self.start_s[idx], self.state[idx], self.out_dt_s, self.step_s)


def _press_model_columns(presses: Sequence[Press], vacuum_kpa: FloatArray, model: KeystrokeModel,
                         block_keys: Sequence[str] | None) -> tuple[FloatArray, FloatArray]:
    """The kernel's columns of commanded presses under `model`, and each press's duration."""
    arm, ends = press_columns(presses, model.arm_profile)
    kp = _model_columns(model.msd, model.effects, vacuum_kpa, block_keys)
    kp[:, K.DIST :] = arm[:, K.DIST :]
    return kp, ends


def flight_starts(
    presses: Sequence[Press], vacuum_kpa: npt.ArrayLike, model: KeystrokeModel, *,
    out_dt_s: float = 1e-3, step_s: float = 1e-4, block_keys: Sequence[str] | None = None,
) -> FlightStarts:
    """The latest start of each press that `simulate_presses(start=...)` can take (see
    `physics.free_flight`): 0, at rest, where the model or the press cannot start in flight.
    The states are for this model and these `out_dt_s`, `step_s` only."""
    presses = list(presses)
    kp, _ = _press_model_columns(presses, _vacuum(vacuum_kpa, len(presses)), model, block_keys)
    start, state = free_flight.starts_in_flight(kp, effect_vector(model.effects), out_dt_s,
                                                _grid(out_dt_s, step_s)[0])
    return FlightStarts(start, state, out_dt_s, step_s)


def simulate_presses(
    presses: Sequence[Press],
    vacuum_kpa: npt.ArrayLike,
    model: KeystrokeModel,
    *,
    out_dt_s: float = 1e-3,
    duration_s: float | None = None,
    step_s: float = 1e-4,
    block_keys: Sequence[str] | None = None,
    start: FlightStarts | None = None,
) -> SimBatch:
    """Simulate keystrokes commanded as presses (time 0 = start of each press's motion, or of
    its simulation, `start`).

    Args:
        presses: the commanded presses.
        vacuum_kpa: one level for all, or one per press.
        model: the keystroke model; `arm_acceleration` selects the trapezoid over the ramp,
            `arm_lag` delays the arm behind its command.
        duration_s: simulated time (default: the longest press plus 0.3 s to settle).
        step_s: largest internal step (the step actually used divides `out_dt_s`).
        block_keys: one label per press for `stiffness_drift` (same label, same drift).
        start: where each press's simulation starts, in flight (`flight_starts` of the same
            presses, model, `out_dt_s` and `step_s`): a press's samples are then at
            start.start_s + t_s, and `duration_s` counts from there.
    """
    presses = list(presses)
    n = len(presses)
    kp, ends = _press_model_columns(presses, _vacuum(vacuum_kpa, n), model, block_keys)
    if duration_s is None:
        duration_s = (float(ends.max()) if n else 0.0) + SETTLE_S
    empty = np.zeros(1)
    # Fast moves cost two more profile evaluations per step: only batches with any pay them.
    mode = 2 if any(p.two_segment for p in presses) else 0
    ep = effect_vector(model.effects)
    if start is not None and np.any(start.start_s != 0.0):
        kp = _started_in_flight(kp, ep, start, out_dt_s, step_s)
    return _run(kp, ep, mode, empty, np.zeros((1, n)), 0.0, float(duration_s), out_dt_s, step_s)


def _started_in_flight(kp: FloatArray, ep: FloatArray, start: FlightStarts, out_dt_s: float,
                       step_s: float) -> FloatArray:
    """`kp` with each press's clock moved to its start and its fingertip's state there."""
    if start.start_s.shape != (kp.shape[0],) or (start.out_dt_s, start.step_s) != (out_dt_s, step_s):
        raise ValueError("start: made for other presses, or another out_dt_s or step_s.")
    if not free_flight.can_start_in_flight(ep, free_flight.has_fast_approach(kp)):
        raise ValueError("start: this model or press starts at rest only (first-order arm lag, "
                         "a yielding finger body or a fast approach).")
    kp = kp.copy()
    kp[:, [K.U1S, K.V1S, K.A1S]] = start.state
    for col in (K.T_DN, K.T_UP, K.T_RE):
        kp[:, col] -= start.start_s
    return kp


def simulate_arm(
    t_s: npt.ArrayLike,
    x0_m: npt.ArrayLike,
    vacuum_kpa: npt.ArrayLike,
    model: KeystrokeModel | Sequence[KeystrokeModel],
    *,
    distance_m: npt.ArrayLike = 0.0,
    key_start_m: npt.ArrayLike = 0.0,
    out_dt_s: float = 1e-3,
    duration_s: float | None = None,
    step_s: float = 1e-4,
    block_keys: Sequence[str] | None = None,
    implicit_damping: bool = False,
) -> SimBatch:
    """Simulate keystrokes driven by given arm traces (e.g. measured TCP z, downward positive).

    The traces are the arm's actual motion, so `arm_lag` and `arm_acceleration` do not apply;
    they are interpolated linearly to the internal step. The fingertip starts at rest at the
    first arm sample, `distance_m` above the key at rest.

    Args:
        t_s: shared sample times (T,), increasing; non-uniform grids are resampled.
        x0_m: arm traces (n, T) or (T,), finite.
        model: the model, or one per trace: models that differ only in their mass, spring and
            damper values (the same effects), e.g. a fit's perturbed parameters side by side. A
            trace's samples are those of its model alone (rows never depend on each other).
        distance_m: fingertip–key gap at the start, scalar or one per trace (a finger body that
            earlier presses yielded, `finger_hysteresis`, hangs its fingertip its set higher).
        key_start_m: where the key starts below its rest position, scalar or one per trace (a
            key that dry friction held part-way down after the previous keystroke): its spring
            is loaded from the start, and the fingertip starts that much farther above it.
            Key positions stay measured from the rest position.
        duration_s: simulated time from t_s[0] (default: to the last sample).
        implicit_damping: take the dampers c0, c1, c2 implicitly (the full step's variant for
            heavily damped parameters, whose explicit step would be tiny: see
            `physics._kernel._make_integrate`).
    """
    t = np.asarray(t_s, dtype=np.float64)
    x = np.atleast_2d(np.asarray(x0_m, dtype=np.float64))
    if t.ndim != 1 or t.size < 2 or x.shape[1] != t.size:
        raise ValueError(f"t_s should be (T,) with T >= 2 and x0_m (n, T); got {t.shape} and {x.shape}.")
    spacing = np.diff(t)
    if not np.all(spacing > 0.0):
        raise ValueError("t_s should be strictly increasing.")
    if not np.all(np.isfinite(x)):
        raise ValueError("x0_m has NaN or inf samples; fill gaps before simulating.")
    dt = float(spacing.min())
    # Uniform within 1e-6 of the step (np.allclose(spacing, dt, 1e-6, 1e-12): no spacing is below dt).
    if float(spacing.max()) - dt > 1e-12 + 1e-6 * dt:
        grid = np.arange(t[0], t[-1] + 0.5 * dt, dt)
        x = np.vstack([np.interp(grid, t, row) for row in x])
        t = grid
    n = x.shape[0]
    vacuum = _vacuum(vacuum_kpa, n)
    if isinstance(model, KeystrokeModel):
        kp = _model_columns(model.msd, model.effects, vacuum, block_keys)
        ep = effect_vector(model.effects)
    else:
        if len(model) != n:
            raise ValueError(f"{len(model)} models for {n} arm traces.")
        ep = effect_vector(model[0].effects)
        kp = np.zeros((n, K.N_KP))
        rows_of: dict[int, tuple[KeystrokeModel, list[int]]] = {}
        for i, m in enumerate(model):
            rows_of.setdefault(id(m), (m, []))[1].append(i)
        for m, rows in rows_of.values():  # each distinct model once, on its rows
            if not np.array_equal(effect_vector(m.effects), ep):
                raise ValueError("models simulated side by side must have the same effects.")
            keys = None if block_keys is None else [block_keys[i] for i in rows]
            kp[rows] = _model_columns(m.msd, m.effects, vacuum[rows], keys)
    kp[:, K.DIST] = np.broadcast_to(np.asarray(distance_m, dtype=np.float64), (n,))
    kp[:, K.X2S] = np.broadcast_to(np.asarray(key_start_m, dtype=np.float64), (n,))
    ep[K.E_LAG_FORM] = K.LAG_NONE
    ep[K.E_LAG_S] = 0.0
    if duration_s is None:
        duration_s = float(t[-1] - t[0])
    return _run(kp, ep, 1, np.ascontiguousarray(t), np.ascontiguousarray(x.T), float(t[0]),
                float(duration_s), out_dt_s, step_s, implicit_damping)
