"""The compiled integrator behind `simulate.py`: one fixed-step loop per keystroke.

Scheme: semi-implicit (symplectic) Euler — velocities first from the forces at the current
positions, then positions from the new velocities. Positions live on the integer steps and the
stored velocities on the half steps, so the spring forces are second-order accurate; damping
forces use the half-step velocity pushed forward half a step with the last acceleration, which
keeps them second-order too (plain symplectic Euler would lag the damping by h/2); heavily
damped models take the dampers implicitly instead (`implicit` in `_make_integrate`). Dry friction
and the key's rest stop are applied as velocity/position projections, which is exact for a
stick-slip contact and needs no regularisation (a tanh friction law would need a tiny step).

Everything is passed as plain arrays so that numba compiles one signature, cached on disk.
Keystrokes are advanced in blocks side by side (time outside, keystroke inside) and the inner
loop is written without branches (effects switch through selects and zero coefficients), so
LLVM turns it into SIMD code: one keystroke's step is a chain of dependent multiply-adds, and
only independent keystrokes in parallel keep the CPU busy. numba has no vector `exp` here, so
a short polynomial one (`_exp`) stands in for it.

Lanes never interact: every per-keystroke quantity (constants, state, arm profile) lives in its
own lane, a partial block is padded with copies of its last keystroke, and the block size (small
for a few keystrokes, else `BLOCK`) only sets how many lanes run side by side. A keystroke's
samples are therefore bit-identical alone and in any batch (tests/physics/test_batch_independence.py).

The module stays one file on purpose: numba's disk cache (cache=True) only watches the source
file of the cached function, so a kernel that inlined helpers from another module would keep
running stale machine code after those helpers changed.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt
from numba import njit

FloatArray = npt.NDArray[np.float64]

# Columns of the per-keystroke parameter table `kp` (n, N_KP).
M1, M2, K0, C0, K1, C1, K2, C2, DIST = 0, 1, 2, 3, 4, 5, 6, 7, 8
# The commanded press: down move (start T_DN) and up move (start T_UP), each a trapezoid with
# acceleration A (0 for a constant-speed ramp), accel time TA, cruise time TC and peak speed VP;
# a two-segment press adds a fast approach (F_*, start 0) and a fast retract (R_*, start T_RE).
# A plain press has empty fast moves (all zero) and T_DN = 0.
D_A, D_TA, D_TC, D_VP, T_UP, U_A, U_TA, U_TC, U_VP = 9, 10, 11, 12, 13, 14, 15, 16, 17
F_A, F_TA, F_TC, F_VP, T_DN, R_A, R_TA, R_TC, R_VP, T_RE = range(18, 28)
# Where the key starts, below its rest position (0 for a key at rest; a key that dry friction
# left part-way down after the previous keystroke starts there, its spring loaded).
X2S = 28
# A keystroke started in flight (`physics.free_flight`): the fingertip's offset from the arm,
# its half-step velocity and its last acceleration at the start (all 0 for a finger at rest).
U1S, V1S, A1S = 29, 30, 31
N_KP = 32

# Entries of the effect vector `ep` (N_EP,): switches (0/1, or a form index) and values; the
# last, E_IMPLICIT, is the scheme `simulate` chose (implicit dampers), not an effect.
(
    E_CONTACT,
    E_BED_ON,
    E_BED_HC,
    E_BED_DEPTH,
    E_BED_K,
    E_BED_C,
    E_PRELOAD,
    E_FRIC_ON,
    E_FRIC_C,
    E_FRIC_S,
    E_FRIC_VS,
    E_STIFF_FORM,
    E_STIFF_BETA,
    E_ADHESION,
    E_LETOFF_F,
    E_LETOFF_X,
    E_LETOFF_W,
    E_LAG_FORM,
    E_LAG_S,
    E_STIFF_Q,
    E_HYST_SHARE,
    E_HYST_YIELD,
    E_HYST_SET,
    E_PRELOAD_W,
    E_ADH_RANGE,
    E_IMPLICIT,
) = range(26)
N_EP = 26

# Rows of the per-block work array: the constants above, then the state of each keystroke.
# One array (keystroke index last) instead of many keeps the compiler free of aliasing doubts,
# which is what lets it vectorise the step across the block.
# S_ZH is the stretch of a yielding finger body's slider spring (hysteresis kernels only).
(S_X0, S_X0P, S_X0N, S_X1, S_X2, S_V1, S_V2, S_A1, S_A2, S_ENG, S_ATT, S_FC, S_V2E, S_ZH) = range(
    N_KP, N_KP + 14
)
N_W = N_KP + 14

STIFF_NONE, STIFF_CUBIC, STIFF_EXP, STIFF_POWER = 0.0, 1.0, 2.0, 3.0
LAG_NONE, LAG_FIRST_ORDER, LAG_DELAY = 0.0, 1.0, 2.0

BLOCK = 16  # keystrokes advanced side by side
SMALL_BLOCK = 4  # the block for a single keystroke (the world's per-trial call)
#: The compiled block sizes: a call runs the smallest that holds its keystrokes (more than
#: `BLOCK` run in blocks of `BLOCK`). What a wider block costs against a narrower one depends on
#: the CPU's vector width (`physics.lanes` measures it); 8 fills one AVX-512 register.
BLOCKS = (SMALL_BLOCK, 8, BLOCK)
_HC_REF_M = 1e-3  # Hunt–Crossley reference indentation: stiffness and damping are quoted at 1 mm


@njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def _move(tau: float, a: float, ta: float, tc: float, vp: float) -> float:
    """Distance covered by a trapezoid move `tau` after its start (branch-free clamps)."""
    u1 = min(max(tau, 0.0), ta)
    u2 = min(max(tau - ta, 0.0), tc)
    u3 = min(max(tau - ta - tc, 0.0), ta)
    return 0.5 * a * u1 * u1 + vp * (u2 + u3) - 0.5 * a * u3 * u3


@njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def _exp(x: float) -> float:
    """exp(x) for x ≤ 4 to ~1e-7 relative (0 below −40): Taylor on x/64, then six squarings.

    Branch-free so that loops calling it vectorise (numba has no SIMD exp without SVML).
    """
    y = min(max(x, -40.0), 4.0) * (1.0 / 64.0)
    e = 1.0 + y * (1.0 + y * (0.5 + y * (1.0 / 6.0 + y * (1.0 / 24.0 + y * (
        1.0 / 120.0 + y * (1.0 / 720.0 + y * (1.0 / 5040.0)))))))
    e = e * e
    e = e * e
    e = e * e
    e = e * e
    e = e * e
    return e * e


@njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def _arm_positions(
    mode: int, w: FloatArray, row: int, trace_t: FloatArray, trace_x0: FloatArray,
    b0: int, nb: int, t: float,
) -> None:
    """Commanded arm positions of keystrokes b0..b0+nb at time t into `w[row]`."""
    if mode != 1:
        # The press is the down move minus the later up move. A ramp is the same formula with
        # a = 0 and no acceleration phase, so every lane takes one path and a keystroke's arm
        # motion never depends on which presses share its block.
        for jj in range(w.shape[1]):
            w[row, jj] = _move(t - w[T_DN, jj], w[D_A, jj], w[D_TA, jj], w[D_TC, jj], w[D_VP, jj]) - _move(
                t - w[T_UP, jj], w[U_A, jj], w[U_TA, jj], w[U_TC, jj], w[U_VP, jj]
            )
        if mode == 2:
            # Two-segment presses add a fast approach before the down move and a fast retract
            # after the up move, in a loop of their own: a plain press in such a batch has empty
            # fast moves and gets exactly 0 added, so its numbers are those of mode 0, bit for bit.
            for jj in range(w.shape[1]):
                w[row, jj] += _move(t, w[F_A, jj], w[F_TA, jj], w[F_TC, jj], w[F_VP, jj]) - _move(
                    t - w[T_RE, jj], w[R_A, jj], w[R_TA, jj], w[R_TC, jj], w[R_VP, jj]
                )
        return
    # A shared uniform grid: one interpolation index for the whole block.
    n_trace = trace_t.shape[0]
    if n_trace == 1:
        for jj in range(nb):
            w[row, jj] = trace_x0[0, b0 + jj]
    else:
        u = min(max((t - trace_t[0]) / (trace_t[1] - trace_t[0]), 0.0), n_trace - 1.0)
        k = min(int(u), n_trace - 2)
        f = u - k
        for jj in range(nb):
            lo = trace_x0[k, b0 + jj]
            w[row, jj] = lo + f * (trace_x0[k + 1, b0 + jj] - lo)
    for jj in range(nb, w.shape[1]):
        w[row, jj] = w[row, nb - 1]


@njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def _load_block(
    w: FloatArray, kp: FloatArray, b0: int, nb: int, mode: int, trace_t: FloatArray,
    trace_x0: FloatArray, t0: float, h: float,
) -> None:
    """Constants of keystrokes b0..b0+nb into `w` (padded with copies of the last) and start state.

    A commanded press (mode 0, 2) starts with the arm where its command was a step earlier as
    the previous position: the same as the start for a press that has not begun to move, the
    arm's own motion for one started in flight. The fingertip hangs from the arm at rest, or as
    the columns U1S, V1S, A1S say.
    """
    for jj in range(w.shape[1]):
        src = b0 + min(jj, nb - 1)
        for col in range(N_KP):
            w[col, jj] = kp[src, col]
        w[M1, jj] = 1.0 / kp[src, M1]  # inverse masses
        w[M2, jj] = 1.0 / kp[src, M2]
    _arm_positions(mode, w, S_X0, trace_t, trace_x0, b0, nb, t0)
    if mode != 1:
        _arm_positions(mode, w, S_X0P, trace_t, trace_x0, b0, nb, t0 - h)
    else:
        for jj in range(w.shape[1]):
            w[S_X0P, jj] = w[S_X0, jj]
    for jj in range(w.shape[1]):
        w[S_X1, jj] = w[S_X0, jj] + w[U1S, jj]
        for row in (S_V2, S_A2, S_ATT, S_FC, S_V2E, S_ZH):
            w[row, jj] = 0.0
        w[S_V1, jj] = w[V1S, jj]
        w[S_A1, jj] = w[A1S, jj]
        w[S_X2, jj] = w[X2S, jj]
        w[S_ENG, jj] = 1.0 if w[S_X1, jj] - w[S_X2, jj] - w[DIST, jj] >= 0.0 else 0.0


@njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def _record(w: FloatArray, b0: int, nb: int, k: int, outs: tuple[FloatArray, ...], part: int) -> None:
    """Write positions (part 0, before the step) or key speed and force (part 1, after it)."""
    out_x0, out_x1, out_x2, out_v2, out_fc = outs
    for jj in range(nb):
        if part == 0:
            out_x0[b0 + jj, k] = w[S_X0, jj]
            out_x1[b0 + jj, k] = w[S_X1, jj]
            out_x2[b0 + jj, k] = w[S_X2, jj]
        else:
            out_v2[b0 + jj, k] = w[S_V2E, jj]
            out_fc[b0 + jj, k] = w[S_FC, jj]


def _make_integrate(block: int, linear: bool, power: bool = False, hysteresis: bool = False,
                    smooth_stop: bool = False, cohesive: bool = False, implicit: bool = False) -> Any:
    """The kernel compiled for blocks of `block` keystrokes and one model class.

    Every argument is a compile-time constant: numba freezes a closure's values into the
    compiled code, so `if linear:` below is settled at compile time and each combination runs a
    loop with no trace of the branches it does not take; its disk cache keys each compiled kernel
    on those values (the closure's cell contents), so all the kernels are cached side by side.

    linear=True is for models without finger- or key-side effects (the study's bilateral spring):
    the same scheme, arm input and outputs, but the key's step is a handful of multiply-adds and
    one select, several times faster than the full step with every effect switched off.
    power=True adds the power-law finger's k1·δ·(βδ)^q: a power of a lane's own value does not
    vectorise, so only models with that form pay for it (the other kernels have no trace of it).
    hysteresis=True adds a yielding finger body (`finger_hysteresis`): the share σ of k0 acts
    through a slider whose spring stretch z follows the body deflection u = x0 − x1 until
    |z| reaches the yield deflection u_y, so the body force is k0·((1 − σ)·u + σ·z). A body
    that earlier presses yielded starts with the slider sprung back to z0 = −f·u_y (f =
    E_HYST_SET) and, at zero force, a set σ·f·u_y/(1 − σ) (`simulate` adds it to the fingertip's
    distance from the key). u and z are kept relative to that start, so the force is
    k0·((1 − σ)·u + σ·z) with z in [−u_y·(1 − f), u_y·(1 + f)]. z is one more state per
    keystroke (row S_ZH), advanced by the exact return mapping of the step's change of u
    (elastic trial, then clamped): branch-free, so the step still vectorises, and exact for a
    deflection that changes linearly over the step. Only models with the effect on pay for it;
    the other kernels are the same code as without the flag.
    smooth_stop=True is for a rest stop that lets go over a width (`key_preload` form smooth: a
    net −P·tanh(x/w)). A tanh in the vectorised step is evaluated whether a lane needs it or not
    (it cost every model with key-side effects 45 %), so only models with that form pay for it.
    cohesive=True is for a skin whose pull fades over a separation range (`adhesion` form
    cohesive); a few multiply-adds, but for every lane of every step (5–10 % measured), so it
    too is a flag.
    implicit=True takes the dampers c0, c1 and c2 at the step's mean speeds (v_old + v_new)/2,
    one 2x2 solve per keystroke and step, instead of at the extrapolated speed. The dampers are
    then stable at any step, so a heavily damped model (a fit bent into dampers hundreds of
    times the finger's) steps at what its springs allow instead of below 1/λ of M⁻¹C. Whether
    the finger's damper is engaged is decided on the solve itself (a unilateral contact
    transmits only what does not pull beyond the skin's hold); dry friction is bounded by the
    solve's response to a force on the key (the fingertip it drags along included); and the
    fingertip is solved again against the key's speed after friction and the rest stop. A felt
    bed's damper stays explicit. The step costs more, so `greybox.prediction.integration_step`
    takes it only where the step grows at least 2x. A run-time switch instead of a flag made
    every explicit step 35 % slower and changed its last bits.
    """

    @njit(cache=True, fastmath=True, error_model="numpy")
    def integrate(
        kp: FloatArray,
        ep: FloatArray,
        mode: int,
        trace_t: FloatArray,
        trace_x0: FloatArray,
        t_start: float,
        h: float,
        n_steps: int,
        out_every: int,
        out_x0: FloatArray,
        out_x1: FloatArray,
        out_x2: FloatArray,
        out_v2: FloatArray,
        out_fc: FloatArray,
    ) -> None:
        """Integrate every keystroke (rows of `kp`) and write the outputs every `out_every` steps.

        mode 0: the arm follows the analytic press in `kp` (mode 2: with fast moves, see
        `_arm_positions`); mode 1: it follows the traces in
        `trace_x0` (shape (len(trace_t), n): keystroke index last), interpolated linearly on the
        uniform grid `trace_t` and held at its ends. Time runs from `t_start` in steps of `h`.
        """
        n = kp.shape[0]
        n_out = out_x1.shape[1]
        outs = (out_x0, out_x1, out_x2, out_v2, out_fc)
        # The effects' switches and values (unused by the linear step, which has none).
        contact = ep[E_CONTACT] != 0.0
        bed_on = 1.0 if ep[E_BED_ON] != 0.0 else 0.0
        bed_hc = ep[E_BED_HC] != 0.0
        x_bed, k_bed, c_bed = ep[E_BED_DEPTH], ep[E_BED_K], ep[E_BED_C]
        preload = ep[E_PRELOAD]
        # A rigid rest stop, or (smooth_stop kernels) one that lets go over the width.
        inv_w_pre = 1.0 / ep[E_PRELOAD_W] if smooth_stop else 0.0
        rest_stop = preload > 0.0 and not smooth_stop
        f_c = ep[E_FRIC_C] if ep[E_FRIC_ON] != 0.0 else 0.0
        stribeck = ep[E_FRIC_ON] != 0.0 and ep[E_FRIC_S] > 0.0
        f_s = ep[E_FRIC_S] if stribeck else f_c
        inv_vs = 1.0 / ep[E_FRIC_VS] if stribeck else 0.0
        beta = ep[E_STIFF_BETA] if ep[E_STIFF_FORM] != STIFF_NONE else 0.0
        exp_on = 1.0 if ep[E_STIFF_FORM] == STIFF_EXP and beta > 0.0 else 0.0
        cubic_on = 1.0 if ep[E_STIFF_FORM] == STIFF_CUBIC and beta > 0.0 else 0.0
        q = ep[E_STIFF_Q]
        inv_beta = 1.0 / beta if exp_on > 0.0 else 0.0
        # Adhesion: a pull-off skin (holds until the pull reaches the force), or (cohesive
        # kernels) one whose pull is a function of the separation s = −pen/range alone,
        # (27/4)·F·s·(1 − s)² for 0 < s < 1 (peak F at s = 1/3, gone at the range).
        pull_off = 0.0 if cohesive else ep[E_ADHESION]
        glued = 1.0 if pull_off > 0.0 else 0.0
        coh_peak = 6.75 * ep[E_ADHESION] if cohesive else 0.0
        inv_range = 1.0 / ep[E_ADH_RANGE] if cohesive else 0.0
        f_let, x_let = ep[E_LETOFF_F], ep[E_LETOFF_X]
        inv_w_let = 1.0 / ep[E_LETOFF_W] if f_let > 0.0 else 0.0
        delay, alpha = arm_lag(ep[E_LAG_FORM], ep[E_LAG_S], h)
        share = ep[E_HYST_SHARE]
        # The slider's range, relative to its stretch at the start (see `_make_integrate`).
        z_lo, z_hi = -ep[E_HYST_YIELD] * (1.0 - ep[E_HYST_SET]), ep[E_HYST_YIELD] * (1.0 + ep[E_HYST_SET])
        half_h = 0.5 * h
        inv_h = 1.0 / h
        inv_2h = 0.5 / h
        # `block` is a compile-time constant (one compiled kernel per block size):
        # with constant row strides the compiler can prove that the rows of `w` do not overlap,
        # and vectorises the step across the lanes.
        w = np.zeros((N_W, block))

        for b0 in range(0, n, block):
            nb = min(block, n - b0)
            _load_block(w, kp, b0, nb, mode, trace_t, trace_x0, t_start - delay, h)
            k_out = 0
            for i in range(n_steps + 1):
                record = k_out < n_out and i == k_out * out_every
                if record:
                    _record(w, b0, nb, k_out, outs, 0)
                _arm_positions(mode, w, S_X0N, trace_t, trace_x0, b0, nb, t_start + (i + 1) * h - delay)
                for jj in range(block):
                    x0_j = w[S_X0, jj]
                    x0_n = x0_j + alpha * (w[S_X0N, jj] - x0_j)
                    v0 = (x0_n - w[S_X0P, jj]) * inv_2h
                    x1_j = w[S_X1, jj]
                    x2_j = w[S_X2, jj]
                    v2_j = w[S_V2, jj]
                    v1e = w[S_V1, jj] + half_h * w[S_A1, jj]
                    v2e = v2_j + half_h * w[S_A2, jj]
                    pen = x1_j - x2_j - w[DIST, jj]
                    # The study's bilateral spring engages at first touch (then it also pulls).
                    eng = max(w[S_ENG, jj], 1.0 if pen >= 0.0 else 0.0)
                    w[S_ENG, jj] = eng

                    # The implicit dampers' terms (set by the full step when `implicit`).
                    c1s, fc0, g1, b1, d11, fric_gain = 0.0, 0.0, 0.0, 0.0, 1.0, 0.0
                    if linear:
                        fc = eng * (w[K1, jj] * pen + w[C1, jj] * (v1e - v2e))
                        a2_j = (fc - w[K2, jj] * x2_j - w[C2, jj] * v2e) * w[M2, jj]
                        v2_new = v2_j + h * a2_j
                        x2_new = x2_j + h * v2_new
                    else:
                        k1 = w[K1, jj]
                        pos = max(pen, 0.0)
                        # Stiffening: cubic k1·δ·(1 + (βδ)²), power k1·δ·(1 + (βδ)^q) or
                        # exponential k1·(e^{βδ} − 1)/β for δ > 0 (slope k1 at touch, then
                        # stiffer); all vanish for β = 0.
                        bp = beta * pos
                        spring = k1 * pen + k1 * pos * (cubic_on * bp * bp)
                        spring += exp_on * k1 * ((_exp(bp) - 1.0) * inv_beta - pos)
                        if power:  # a compile-time constant
                            spring += k1 * pos * bp**q
                        raw = spring + w[C1, jj] * (v1e - v2e)
                        # Unilateral (pushes only; an adhesive skin pulls until the pull-off force)
                        # or the bilateral spring.
                        touching = pen > 0.0
                        attached = w[S_ATT, jj]
                        holds = min(attached, 1.0 if raw >= -pull_off else 0.0)
                        fc_uni = max(raw, -pull_off) if touching else holds * raw
                        pull = 0.0
                        if cohesive:  # a compile-time constant
                            sep = min(max(-pen * inv_range, 0.0), 1.0)
                            pull = coh_peak * sep * (1.0 - sep) * (1.0 - sep)
                            fc_uni -= pull
                        w[S_ATT, jj] = glued if touching else holds
                        fc = fc_uni if contact else eng * raw

                        # The key's spring is preloaded against its rest stop: the down-weight always
                        # acts, and the stop (below) holds the key at rest until the finger pushes harder
                        # (a smooth stop instead hands the down-weight over within its width).
                        if smooth_stop:  # a compile-time constant
                            f2 = fc - w[K2, jj] * x2_j - w[C2, jj] * v2e - preload * math.tanh(x2_j * inv_w_pre)
                        else:
                            f2 = fc - w[K2, jj] * x2_j - w[C2, jj] * v2e - preload
                        # Keybed: a felt stop, linear spring-damper or Hunt–Crossley (force and damping
                        # grow with indentation, so there is no force jump on impact); it never pulls.
                        pen_bed = max(x2_j - x_bed, 0.0)
                        fb = k_bed * pen_bed + c_bed * v2e
                        fb *= math.sqrt(pen_bed * (1.0 / _HC_REF_M)) if bed_hc else 1.0
                        f2 -= bed_on * max(fb, 0.0) if pen_bed > 0.0 else 0.0
                        # Let-off: a bump that resists the key on its way down only.
                        z = (x2_j - x_let) * inv_w_let
                        f2 -= f_let * _exp(-z * z) if v2e > 0.0 else 0.0

                        v2_free = v2_j + h * f2 * w[M2, jj]
                        if implicit:  # a compile-time constant
                            # The dampers at the step's mean speeds u = (v_old + v_new)/2: the
                            # arm's c0, the key's c2 and the finger's c1 (where it transmits force
                            # this step) in one 2x2 solve; every other force as above.
                            g1 = half_h * w[M1, jj]
                            g2 = half_h * w[M2, jj]
                            if hysteresis:
                                u_b = x0_j - x1_j
                                b1 = w[K0, jj] * (u_b - share * (u_b - w[S_ZH, jj])) + w[C0, jj] * v0
                            else:
                                b1 = w[K0, jj] * (x0_j - x1_j) + w[C0, jj] * v0
                            f2r = f2 - fc + w[C2, jj] * v2e  # the key's forces but the finger's and c2
                            # Is the finger's damper engaged? Solve as if it were: a unilateral
                            # contact transmits only what does not pull beyond the skin's hold.
                            c1f = w[C1, jj]
                            fc0 = spring - pull
                            r1 = w[S_V1, jj] + g1 * (b1 - fc0)
                            r2 = v2_j + g2 * (f2r + fc0)
                            d11 = 1.0 + g1 * (w[C0, jj] + c1f)
                            d22 = 1.0 + g2 * (w[C2, jj] + c1f)
                            u2 = (d11 * r2 + g2 * c1f * r1) / (d11 * d22 - g1 * g2 * c1f * c1f)
                            raw_i = spring + c1f * ((r1 + g1 * c1f * u2) / d11 - u2)
                            grip = 1.0 if touching else attached
                            cpl = (grip if raw_i >= -pull_off else 0.0) if contact else eng
                            if contact:
                                w[S_ATT, jj] = glued if touching else cpl
                            # The engaged finger's elastic force, or a released contact's hold.
                            fc0 = cpl * spring + (1.0 - cpl) * (-pull_off if touching else 0.0) - pull
                            c1s = cpl * c1f
                            r1 = w[S_V1, jj] + g1 * (b1 - fc0)
                            r2 = v2_j + g2 * (f2r + fc0)
                            d11 = 1.0 + g1 * (w[C0, jj] + c1s)
                            d22 = 1.0 + g2 * (w[C2, jj] + c1s)
                            det = d11 * d22 - g1 * g2 * c1s * c1s
                            v2_free = 2.0 * (d11 * r2 + g2 * c1s * r1) / det - v2_j
                            # A force f on the key changes its new speed by f·(h/m2)·d11/det in
                            # this solve (the finger it drags along included): friction's bound.
                            fric_gain = 2.0 * g2 * d11 / det
                        # Dry friction as an impulse bounded by h·F/m: if it can stop the key within
                        # the step the key sticks (exact Coulomb), else it slides against the motion.
                        r = v2_j * inv_vs
                        f_fric = f_c + (f_s - f_c) * _exp(-r * r)
                        dv = h * f_fric * w[M2, jj]
                        if implicit:  # a compile-time constant
                            dv = f_fric * fric_gain
                        v2_new = math.copysign(max(abs(v2_free) - dv, 0.0), v2_free)
                        x2_new = x2_j + h * v2_new
                        # A preloaded key cannot rise above its rest stop (a plastic felt rail).
                        at_stop = rest_stop and x2_new <= 0.0
                        v2_new = 0.0 if at_stop else v2_new
                        x2_new = 0.0 if at_stop else x2_new
                        a2_j = (v2_new - v2_j) * inv_h

                    if hysteresis:  # a compile-time constant
                        u_j = x0_j - x1_j
                        z_j = w[S_ZH, jj]
                        body = w[K0, jj] * (u_j - share * (u_j - z_j))
                        a1_j = (body + w[C0, jj] * (v0 - v1e) - fc) * w[M1, jj]
                    else:
                        a1_j = (w[K0, jj] * (x0_j - x1_j) + w[C0, jj] * (v0 - v1e) - fc) * w[M1, jj]
                    if implicit and not linear:
                        # The fingertip against the key's actual mean speed (after friction and
                        # the rest stop): the first row of the solve again, then its force.
                        v2e = 0.5 * (v2_j + v2_new)
                        u1 = (w[S_V1, jj] + g1 * (b1 - fc0 + c1s * v2e)) / d11
                        fc = fc0 + c1s * (u1 - v2e)
                        a1_j = (b1 - fc - w[C0, jj] * u1) * w[M1, jj]
                    v1_j = w[S_V1, jj] + h * a1_j
                    w[S_FC, jj] = fc
                    w[S_V2E, jj] = v2e
                    w[S_A1, jj] = a1_j
                    w[S_A2, jj] = a2_j
                    w[S_V1, jj] = v1_j
                    w[S_V2, jj] = v2_new
                    x1_n = x1_j + h * v1_j
                    if hysteresis:
                        # The slider sticks while its spring is within the yield, else slips.
                        z_n = z_j + ((x0_n - x1_n) - u_j)
                        w[S_ZH, jj] = min(max(z_n, z_lo), z_hi)
                    w[S_X1, jj] = x1_n
                    w[S_X2, jj] = x2_new
                    w[S_X0P, jj] = x0_j
                    w[S_X0, jj] = x0_n
                if record:
                    _record(w, b0, nb, k_out, outs, 1)
                    k_out += 1

    return integrate


@njit(cache=True, fastmath=True, error_model="numpy")
def arm_lag(form: float, lag_s: float, h: float) -> tuple[float, float]:
    """(delay, alpha): a pure arm delay, or the exact per-step factor of a first-order lag."""
    if form == LAG_DELAY:
        return lag_s, 1.0
    if form == LAG_FIRST_ORDER and lag_s > 0.0:
        return 0.0, -math.expm1(-h / lag_s)
    return 0.0, 1.0


# One compiled kernel per block size and model class (numba caches each on disk; a kernel is
# compiled, or loaded from the cache, on its first call only): the linear step, and the full
# step with the flags (power, hysteresis, smooth_stop, cohesive, implicit) of `_make_integrate`.
FULL_FLAGS: tuple[tuple[bool, bool, bool, bool, bool], ...] = tuple(
    (power, hysteresis, smooth_stop, cohesive, implicit)
    for power in (False, True) for hysteresis in (False, True)
    for smooth_stop in (False, True) for cohesive in (False, True) for implicit in (False, True)
)
integrate_linear = {b: _make_integrate(b, linear=True) for b in BLOCKS}
integrate_full = {flags: {b: _make_integrate(b, False, *flags) for b in BLOCKS} for flags in FULL_FLAGS}
