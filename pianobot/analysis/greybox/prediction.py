"""What a drive of the forward model predicts for a batch, and how finely it must integrate.

A `Prediction` holds the model's fingertip and key at the batch's frames (when the batch has
trajectories) and its MIDI outcome per keystroke (when the drive reads the piano): the
on-velocity before rounding (so fits see a smooth function of the parameters), note-on time,
hold, and the margin by which the key passed (> 0) or missed (< 0) the trigger depth.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pianobot.physics.model import KeystrokeModel
from pianobot.physics.simulate import BATCH_LANES, LANE_BLOCKS, SMALL_LANES, block_for

FloatArray = npt.NDArray[np.float64]

#: Finger compression at which a stiffening finger's stiffness is judged for the step, when the
#: data do not show it (MIDI only).
TYPICAL_COMPRESSION_M = 5e-3


def _nan(n: int) -> FloatArray:
    return np.full(n, np.nan)


@dataclass(frozen=True)
class Prediction:
    """Model outputs for a batch (see the module docstring); NaN where not predicted."""

    x1_m: FloatArray  # (n, T) fingertip at the frames
    x2_m: FloatArray  # (n, T) key at the frames
    v2_mps: FloatArray  # (n, T) key speed (empty when not asked for)
    force_n: FloatArray  # (n, T) finger force on the key
    on_velocity: FloatArray  # (n,) before rounding; NaN where silent
    t_on_s: FloatArray  # (n,) note-on after motion start
    hold_s: FloatArray  # (n,) note-off minus note-on
    margin_m: FloatArray  # (n,) deepest key travel minus the trigger depth

    @classmethod
    def trajectories(cls, x1_m: FloatArray, x2_m: FloatArray, v2_mps: FloatArray | None = None,
                     force_n: FloatArray | None = None) -> Prediction:
        """Trajectories only (no MIDI read)."""
        n = x1_m.shape[0]
        empty = np.zeros((n, 0))
        return cls(x1_m, x2_m, empty if v2_mps is None else v2_mps, empty if force_n is None else force_n,
                   _nan(n), _nan(n), _nan(n), _nan(n))

    @property
    def sounded(self) -> npt.NDArray[np.bool_]:
        """Keystrokes the model sounds."""
        return np.asarray(np.isfinite(self.on_velocity), dtype=bool)


#: Largest internal integration step of both drives (measured arm, commanded). The fastest mode
#: of the published model is near 20 Hz; at 0.2 ms the semi-implicit scheme's phase error over a
#: keystroke stays far below mocap noise (a stiffer or more heavily damped model takes a smaller
#: one: `integration_step_s`). A coarser cap for smooth models (0.5 ms: 2.5x fewer steps, the key
#: within 0.12 um of a 50 us reference) was tried twice and lost findings both times: the study's
#: zzz40 let-off (held-out shrink 29.4 % against 31 %), and, with every first-order effect kept at
#: 0.2 ms, an independent weak rest stop, whose joint fit from the coarser base model stopped in
#: another basin (preload 0.69 N, interval including 0, against 0.12 N, ΔIC 4,785).
SIM_STEP_S = 2e-4
#: Keystrokes simulated side by side at most (the simulator's SIMD block): rows are grouped by
#: length (`length_groups`), so short keystrokes are not integrated through the long ones' rest.
GROUP = BATCH_LANES
#: What a step of each block costs against one of the 4-lane block when nothing was measured:
#: proportional to the lanes (no gain from running them side by side). Fits pass the costs
#: `physics.lanes.block_costs` measures for their kernel on this machine.
PROPORTIONAL_COSTS: dict[int, float] = {block: block / SMALL_LANES for block in LANE_BLOCKS}
#: The cost of a call of its own, in 4-lane steps.
CALL_COST_STEPS = 1000.0

#: The step is kept below these fractions of the model's fastest time scales. Oscillation
#: (h·ω, ω the largest natural frequency): accuracy of the phase over a keystroke, 0.2 is ~30
#: steps per period. Damping (h·λ, λ the largest eigenvalue of M⁻¹C): the scheme's damping force
#: is explicit, stable below h·λ ≈ 1 (measured); an overdamped fast mode only has to relax
#: stably, its transient lasting 1/λ, so half the limit is accurate to far below mocap noise.
STEP_PER_PERIOD = 0.2
STEP_PER_DAMPING_TIME = 0.5
#: The implicit-damper scheme is taken where it lengthens the step at least this much (it costs
#: more per step; below this gain the explicit scheme and its numbers stay).
IMPLICIT_GAIN = 2.0


def _largest_eigenvalue(a11: float, a12: float, a21: float, a22: float) -> float:
    """Largest real part of the eigenvalues of [[a11, a12], [a21, a22]] (a similar-to-symmetric
    M⁻¹K or M⁻¹C: the eigenvalues are real)."""
    half = 0.5 * (a11 + a22)
    disc = half * half - (a11 * a22 - a12 * a21)
    return half + math.sqrt(max(disc, 0.0))


def integration_step_s(model: KeystrokeModel, vacuum_kpa: FloatArray, largest_s: float,
                       compression_m: float = TYPICAL_COMPRESSION_M) -> float:
    """The integration step for the model at these vacuum levels: `largest_s` or less, so that
    the explicit scheme stays stable and accurate (`STEP_PER_PERIOD`, `STEP_PER_DAMPING_TIME`).
    A stiffening finger is judged at `compression_m`, the largest compression the keystrokes
    reach (a sharp power of the compression is stiff only where it is reached).

    The time scales are those of the 2-DoF system with every spring and damper it may engage at
    once (the arm coupling k0, c0 on the fingertip, the finger k1, c1 between fingertip and key
    (or a cohesive skin's pull at its steepest, where that is steeper), the key's k2, c2 and the
    stiffest effect: an end stop, a let-off bump's slope, a smooth rest stop's slope at rest
    (P/w), a stiffening finger at `compression_m`), from the exact eigenvalues of M⁻¹K and M⁻¹C.
    A fit may try stiff, heavily damped or strongly stiffening parameters; a bound on the
    diagonal alone would either miss the coupled mode or (as before) take a step several times
    smaller than needed.
    """
    return _steps(model, vacuum_kpa, largest_s, compression_m)[0]


def integration_step(model: KeystrokeModel, vacuum_kpa: FloatArray, largest_s: float,
                     compression_m: float = TYPICAL_COMPRESSION_M) -> tuple[float, bool]:
    """(step, implicit dampers): `integration_step_s`, or, where the dampers alone hold that
    step below 1/`IMPLICIT_GAIN` of what the springs allow, the larger step of the scheme that
    takes c0, c1 and c2 implicitly (`simulate_arm(..., implicit_damping=True)`).

    A fit that has no effect for what it sees can bend into dampers hundreds of times the
    finger's (c1 147 N·s/m on a 7 g fingertip, measured on an independent stiffening take):
    the explicit step is then 13 µs where the springs allow the full 200. The implicit scheme
    at 200 µs stays within 1.2e-5 mm RMS of the explicit one at a quarter of its step on that
    model (mocap noise is ~3e-3 mm). Models whose dampers do not bind keep the explicit scheme,
    and their numbers."""
    explicit, implicit = _steps(model, vacuum_kpa, largest_s, compression_m)
    return (implicit, True) if implicit >= IMPLICIT_GAIN * explicit else (explicit, False)


def _steps(model: KeystrokeModel, vacuum_kpa: FloatArray, largest_s: float,
           compression_m: float) -> tuple[float, float]:
    """The explicit scheme's step and the implicit-damper scheme's (a felt bed's damper stays
    explicit in both)."""
    fx = model.effects
    k_bed = fx.value("keybed", "bed_stiffness_npm", 0.0)
    c_bed = fx.value("keybed", "bed_damping_nspm", 0.0)
    width = fx.value("letoff", "letoff_width_m", 1.0)
    k_let = fx.value("letoff", "letoff_force_n", 0.0) / max(width, 1e-6)
    pre_w = fx.value("key_preload", "preload_width_m", 0.0, form="smooth")
    k_pre = fx.value("key_preload", "preload_n", 0.0) / pre_w if pre_w > 0 else 0.0
    # A cohesive skin's pull, between fingertip and key, is steepest as they part: 27/4·F/range.
    adh_range = fx.value("adhesion", "adhesion_range_m", 0.0, form="cohesive")
    k_adh = 6.75 * fx.value("adhesion", "pull_off_force_n", 0.0) / adh_range if adh_range > 0 else 0.0
    beta = fx.value("finger_stiffening", "stiffening_per_m", 0.0)
    grow = 1.0
    if beta > 0:
        bd = beta * compression_m
        form = fx.form("finger_stiffening")
        q = fx.value("finger_stiffening", "stiffening_exponent", 2.0) if form == "power" else 2.0
        # The spring's slope at that compression, over k1.
        grow = math.exp(min(bd, 30.0)) if form == "exponential" else 1.0 + (q + 1.0) * min(bd, 30.0) ** q
    explicit = implicit = largest_s
    for p in np.unique(vacuum_kpa):
        lp = model.msd.at(float(p))
        # The skin pulls only once the finger has left the key, where the finger's spring is off.
        k1, c1 = max(lp.k1_npm * grow, k_adh), lp.c1_nspm
        m1, m2 = lp.m1_kg, lp.m2_kg
        omega = math.sqrt(max(_largest_eigenvalue((lp.k0_npm + k1) / m1, -k1 / m1, -k1 / m2,
                                                  (k1 + lp.k2_npm + k_bed + k_let + k_pre) / m2), 0.0))
        damping = _largest_eigenvalue((lp.c0_nspm + c1) / m1, -c1 / m1, -c1 / m2, (c1 + lp.c2_nspm + c_bed) / m2)
        springs = STEP_PER_PERIOD / max(omega, 1e-300)
        explicit = min(explicit, springs, STEP_PER_DAMPING_TIME / max(damping, 1e-300))
        implicit = min(implicit, springs, STEP_PER_DAMPING_TIME * m2 / max(c_bed, 1e-300))
    return explicit, implicit


def length_groups(lengths: npt.ArrayLike, block_costs: Mapping[int, float] | None = None) -> list[npt.NDArray[np.intp]]:
    """Rows to simulate together, longest first: every row of a group is integrated as long as
    its longest one, so the rows are split where that costs least.

    `lengths` are the rows' simulated lengths in steps. A group runs the smallest compiled block
    that holds it (`physics.simulate.block_for`: 4, 8 or 16 lanes), a step of which costs
    `block_costs[block]` 4-lane steps (`physics.lanes.block_costs` measures them; default
    `PROPORTIONAL_COSTS`); each call costs `CALL_COST_STEPS` more. The split is exact (dynamic
    programming over the rows sorted by length), and a row's samples do not depend on its
    companions, so only the time changes. A take whose slowest presses last five times its
    fastest simulates its 16 training keystrokes as four groups of four instead of one block
    of 16 as long as the slowest: 1.3x less time per evaluation on the independent suite's
    takes (measured with the 4- and 16-lane blocks alone, at 4x for the wider one). With the
    costs measured here (AVX-512) and the 8-lane block, discovery on the suite's 18 slowest
    takes spends 1.13x less CPU than with those constants.
    """
    n_steps = np.ascontiguousarray(lengths, dtype=np.float64)
    costs = PROPORTIONAL_COSTS if block_costs is None else block_costs
    per_size = tuple(float(costs[block_for(size)]) for size in range(1, GROUP + 1))
    # A fit asks again with the same lengths at every evaluation (they change only with the
    # step): the split of 135 rows costs ~1.4 ms, as much as a tenth of an evaluation.
    return [rows.copy() for rows in _length_groups(n_steps.tobytes(), per_size)]


@functools.lru_cache(maxsize=64)
def _length_groups(lengths: bytes, per_size: tuple[float, ...]) -> tuple[npt.NDArray[np.intp], ...]:
    n_steps = np.frombuffer(lengths, dtype=np.float64)
    order = np.argsort(-n_steps, kind="stable")
    longest = n_steps[order]
    n = order.size
    best = np.full(n + 1, np.inf)
    best[0] = 0.0
    cut = np.zeros(n + 1, dtype=np.intp)
    for end in range(1, n + 1):
        for size in range(1, min(GROUP, end) + 1):
            start = end - size
            cost = best[start] + per_size[size - 1] * longest[start] + CALL_COST_STEPS
            if cost < best[end]:
                best[end], cut[end] = cost, start
    groups = []
    end = n
    while end > 0:
        groups.append(order[cut[end] : end])
        end = cut[end]
    return tuple(groups[::-1])
