"""The truth lab's integrator: the finger–key chain as a hybrid system, stepped by classical RK4.

Smooth forces (springs, dampers, Hunt–Crossley and power-law stops, LuGre bristles, Bouc–Wen
hysteresis, cohesive adhesion) go into one right-hand side. Non-smooth laws are *modes*, frozen
during a step, each with a switching function that must stay ≥ 0 while the mode holds:

| mode | holds while | on crossing |
|---|---|---|
| TOUCH (finger on key) | gap s = x1 − x2 − distance ≥ 0 (with pull-off adhesion: or pull > −F) | apart |
| apart | s < 0 | touch (force jumps by c1·ṡ: exactly at the event) |
| AT_STOP (key on its rest rail) | finger force ≤ preload | free; a free key rising past 0 lands on the rail (v = 0) |
| STUCK (key held by dry friction) | applied force ≤ static friction | slips in the force's direction |
| slipping in direction d | d·v2 ≥ 0 | sticks if the force is below static friction, else reverses |
| DESC (key descending, let-off acts) | v2 has the mode's sign | flips |
| BED_IN (linear stop engaged) | indentation has the mode's sign | flips |

A step that ends with a switching function < 0 is bisected on its own length (RK4 from the
step's start with a shorter step, to 1e-10 s) and the state is advanced to just past the
crossing, where the modes are updated; the rest of the step is then taken. Steps also land on
every time the arm's commanded acceleration jumps. So no step straddles a discontinuity and
RK4 keeps its fourth order; the step (≈ 21 µs) resolves the stiffest smooth element in use.

Everything is passed as plain arrays (slots below) so numba compiles one signature. The
compiled code stays in this one file on purpose: numba's disk cache only watches the source
file of each function, so splitting the force laws from the stepper could run stale code.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

FloatArray = npt.NDArray[np.float64]

# Slots of the plain arrays the compiled code takes (parameters, state, modes, records). They
# live here, not in a module of their own, so that editing them invalidates numba's cache.
# --- parameters (float64 vector) -------------------------------------------------------------
M1, M2, K0, C0, K1, C1, K2, C2, DIST = range(9)
ARM_KIND, ARM_TAU, ARM_WN, ARM_ZETA = range(9, 13)
STIFF_FORM, STIFF_B, STIFF_SREF, STIFF_Q = range(13, 17)
ADH_FORM, ADH_F, ADH_RANGE = range(17, 20)
HYS_ON, HYS_ALPHA, HYS_UY, HYS_N = range(20, 24)
BED_FORM, BED_X, BED_K, BED_C, BED_N = range(24, 29)
PRE_FORM, PRE_W, PRE_DELTA, PRE_DAMP = range(29, 33)
LET_FORM, LET_F, LET_X, LET_W, LET_WD = range(33, 38)
FR_FORM, FR_FC, FR_FS, FR_VS, FR_S0, FR_S1, FR_S2 = range(38, 45)
N_PARAMS = 45

# --- continuous state ------------------------------------------------------------------------
X1, V1, X2, V2, XA, VA, ZF, ZH = range(8)
N_STATE = 8

# --- discrete modes (float64 vector so one array type serves all) ----------------------------
TOUCH, STUCK, SLIP_DIR, AT_STOP, DESC, BED_IN = range(6)
N_MODES = 6

# --- recorded channels -----------------------------------------------------------------------
OUT_T, OUT_XC, OUT_XA, OUT_VA, OUT_X1, OUT_V1, OUT_X2, OUT_V2, OUT_FC, OUT_F0 = range(10)
N_OUT = 10
OUT_NAMES = ("t_s", "x_cmd_m", "x0_m", "v0_mps", "x1_m", "v1_mps", "x2_m", "v2_mps",
             "contact_n", "body_n")  # fmt: skip

# --- form codes ------------------------------------------------------------------------------
ARM_EXACT, ARM_LAG, ARM_SERVO, ARM_DELAY = 0, 1, 2, 3
STIFF_NONE, STIFF_EXP, STIFF_POWER = 0, 1, 2
ADH_NONE, ADH_PULL_OFF, ADH_COHESIVE = 0, 1, 2
BED_NONE, BED_LINEAR, BED_HC15, BED_POWER = 0, 1, 2, 3
PRE_NONE, PRE_REST_STOP, PRE_FELT = 0, 1, 2
LET_NONE, LET_GAUSS, LET_TRIP = 0, 1, 2
FR_NONE, FR_STRIBECK, FR_LUGRE = 0, 1, 2

BED_REF_M = 1e-3  # reference indentation of the Hunt–Crossley and power-law stops

BISECT_TOL_S = 1e-10
MAX_EVENTS_PER_STEP = 16
QUIET_OMEGA_H = 0.1  # long steps only while (fastest mode's ω) × step stays below this
QUIET_GAP_M = 1e-5  # margin a finger off the key keeps from it over a long step
QUIET_MARGIN_M = 5e-4  # no long steps this close to a stop
QUIET_LETOFF_M = 3e-3  # ... or to the let-off bump


@njit(cache=True, _nrt=False, inline="always")
def _cmd(t: float, moves: FloatArray, hint: npt.NDArray[np.int64]) -> tuple[float, float]:
    """Commanded position and speed (the trapezoids of `arm.move_table`)."""
    n = moves.shape[0]
    if n == 0:
        return 0.0, 0.0
    i = hint[0]
    while i > 0 and t < moves[i, 0]:
        i -= 1
    while i + 1 < n and t >= moves[i + 1, 0]:
        i += 1
    hint[0] = i
    t0, ramp, cruise, total = moves[i, 0], moves[i, 1], moves[i, 2], moves[i, 3]
    peak, acc, sign, xs = moves[i, 4], moves[i, 5], moves[i, 6], moves[i, 7]
    tau = t - t0
    if tau < 0.0:
        return xs, 0.0
    d = peak * (ramp + cruise)
    if tau >= total:
        return xs + sign * d, 0.0
    if tau < ramp:
        return xs + sign * 0.5 * acc * tau * tau, sign * acc * tau
    if tau < ramp + cruise:
        return xs + sign * (0.5 * acc * ramp * ramp + peak * (tau - ramp)), sign * peak
    r = total - tau
    return xs + sign * (d - 0.5 * acc * r * r), sign * acc * r


@njit(cache=True, _nrt=False, inline="always")
def _arm(
    t: float, y: FloatArray, p: FloatArray, moves: FloatArray, hint: npt.NDArray[np.int64]
) -> tuple[float, float, float, float]:
    """(commanded x, v, actual arm x, v)."""
    xc, vc = _cmd(t, moves, hint)
    kind = int(p[ARM_KIND])
    if kind == ARM_EXACT:
        return xc, vc, xc, vc
    if kind == ARM_DELAY:
        xd, vd = _cmd(t - p[ARM_TAU], moves, hint)
        return xc, vc, xd, vd
    if kind == ARM_LAG:
        return xc, vc, y[XA], (xc - y[XA]) / p[ARM_TAU]
    return xc, vc, y[XA], y[VA]


@njit(cache=True, _nrt=False, inline="always")
def _contact(y: FloatArray, p: FloatArray, m: FloatArray) -> tuple[float, float]:
    """(force the finger puts on the key, downward; the unclipped spring-damper force)."""
    s = y[X1] - y[X2] - p[DIST]
    if m[TOUCH] > 0.5:
        k1 = p[K1]
        form = int(p[STIFF_FORM])
        if s > 0.0 and form == STIFF_EXP:
            b = p[STIFF_B]
            spring = k1 * math.expm1(b * s) / b
        elif s > 0.0 and form == STIFF_POWER:
            spring = k1 * s * (1.0 + (s / p[STIFF_SREF]) ** p[STIFF_Q])
        else:
            spring = k1 * s
        raw = spring + p[C1] * (y[V1] - y[V2])
        pull = p[ADH_F] if int(p[ADH_FORM]) == ADH_PULL_OFF else 0.0
        return max(raw, -pull), raw
    if int(p[ADH_FORM]) == ADH_COHESIVE and s < 0.0:
        q = -s / p[ADH_RANGE]
        return -p[ADH_F] * q * math.exp(1.0 - q), 0.0
    return 0.0, 0.0


@njit(cache=True, _nrt=False, inline="always")
def _trip(x: float, xl: float, rise: float, drop: float) -> float:
    """Let-off trip shape: smooth rise over `rise` up to the trip depth, faster fall over `drop`."""
    if x <= xl - rise or x >= xl + drop:
        return 0.0
    if x < xl:
        u = (x - (xl - rise)) / rise
        return u * u * (3.0 - 2.0 * u)
    u = (x - xl) / drop
    return 1.0 - u * u * (3.0 - 2.0 * u)


@njit(cache=True, _nrt=False, inline="always")
def _key_forces(x2: float, v2: float, p: FloatArray, m: FloatArray) -> float:
    """Downward force on the key from everything but the finger and friction."""
    f = -p[K2] * x2 - p[C2] * v2
    pre = int(p[PRE_FORM])
    if pre == PRE_REST_STOP:
        f -= p[PRE_W]
    elif pre == PRE_FELT:
        # The return spring's preload presses the key up into a felt rail; at rest the felt is
        # compressed by PRE_DELTA and pushes back with exactly the preload.
        f -= p[PRE_W]
        comp = p[PRE_DELTA] - x2
        if comp > 0.0:
            felt = p[PRE_W] * (comp / p[PRE_DELTA]) ** 1.5 * (1.0 - p[PRE_DAMP] * v2)
            if felt > 0.0:
                f += felt
    bed = int(p[BED_FORM])
    if bed != BED_NONE:
        pen = x2 - p[BED_X]
        fb = 0.0
        if bed == BED_LINEAR:
            if m[BED_IN] > 0.5:
                fb = p[BED_K] * pen + p[BED_C] * v2
        elif pen > 0.0:
            r = pen / BED_REF_M
            if bed == BED_HC15:
                fb = (p[BED_K] * pen + p[BED_C] * v2) * math.sqrt(r)
            else:  # power law with Hunt–Crossley damping: F1mm·r^n·(1 + λ·v)
                fb = p[BED_K] * r ** p[BED_N] * (1.0 + p[BED_C] * v2)
        if fb > 0.0:
            f -= fb
    let = int(p[LET_FORM])
    if let != LET_NONE and m[DESC] > 0.5:
        if let == LET_GAUSS:
            z = (x2 - p[LET_X]) / p[LET_W]
            f -= p[LET_F] * math.exp(-z * z)
        else:
            f -= p[LET_F] * _trip(x2, p[LET_X], p[LET_W], p[LET_WD])
    return f


@njit(cache=True, _nrt=False, inline="always")
def _stribeck(v: float, p: FloatArray) -> float:
    r = v / p[FR_VS]
    return p[FR_FC] + (p[FR_FS] - p[FR_FC]) * math.exp(-r * r)


@njit(cache=True, _nrt=False, inline="always")
def _body(y: FloatArray, xa: float, va: float, p: FloatArray) -> float:
    """Force of the finger body on the finger mass (downward)."""
    u = xa - y[X1]
    ud = va - y[V1]
    if p[HYS_ON] > 0.5:
        a = p[HYS_ALPHA]
        return p[K0] * (a * u + (1.0 - a) * y[ZH]) + p[C0] * ud
    return p[K0] * u + p[C0] * ud


@njit(cache=True, _nrt=False)
def _rhs(
    t: float,
    y: FloatArray,
    p: FloatArray,
    m: FloatArray,
    moves: FloatArray,
    hint: npt.NDArray[np.int64],
    dy: FloatArray,
    aux: FloatArray,
) -> None:
    """dy = f(t, y) under modes m; aux = (x_cmd, x_arm, v_arm, contact force, body force)."""
    xc, vc, xa, va = _arm(t, y, p, moves, hint)
    fc, _ = _contact(y, p, m)
    f0 = _body(y, xa, va, p)
    dy[X1] = y[V1]
    dy[V1] = (f0 - fc) / p[M1]
    dy[ZF] = 0.0
    if m[AT_STOP] > 0.5 or m[STUCK] > 0.5:
        dy[X2] = 0.0
        dy[V2] = 0.0
    else:
        v2 = y[V2]
        f2 = fc + _key_forces(y[X2], v2, p, m)
        fr = int(p[FR_FORM])
        if fr == FR_STRIBECK:
            f2 -= m[SLIP_DIR] * _stribeck(v2, p)
        elif fr == FR_LUGRE:
            z = y[ZF]
            zd = v2 - p[FR_S0] * abs(v2) * z / _stribeck(v2, p)
            f2 -= p[FR_S0] * z + p[FR_S1] * zd + p[FR_S2] * v2
            dy[ZF] = zd
        dy[X2] = v2
        dy[V2] = f2 / p[M2]
    kind = int(p[ARM_KIND])
    if kind == ARM_LAG:
        dy[XA] = (xc - y[XA]) / p[ARM_TAU]
        dy[VA] = 0.0
    elif kind == ARM_SERVO:
        wn = p[ARM_WN]
        dy[XA] = y[VA]
        dy[VA] = wn * wn * (xc - y[XA]) + 2.0 * p[ARM_ZETA] * wn * (vc - y[VA])
    else:
        dy[XA] = 0.0
        dy[VA] = 0.0
    if p[HYS_ON] > 0.5:
        # Bouc–Wen with β = γ = 1/2: the hysteretic part saturates at HYS_UY when loading and
        # unloads elastically, so loading and unloading follow different curves.
        ud = va - y[V1]
        zh = y[ZH]
        q = abs(zh / p[HYS_UY]) ** p[HYS_N]
        dy[ZH] = ud - 0.5 * q * (abs(ud) * math.copysign(1.0, zh) + ud)
    else:
        dy[ZH] = 0.0
    aux[0] = xc
    aux[1] = xa
    aux[2] = va
    aux[3] = fc
    aux[4] = f0


@njit(cache=True, _nrt=False, inline="always")
def _applied(y: FloatArray, p: FloatArray, m: FloatArray) -> float:
    """Force on a key held at rest (v2 = 0), friction excluded: what friction must resist."""
    fc, _ = _contact(y, p, m)
    return fc + _key_forces(y[X2], 0.0, p, m)


@njit(cache=True, _nrt=False)
def _valid(y: FloatArray, p: FloatArray, m: FloatArray) -> bool:
    """Whether every mode still holds at state y (all switching functions ≥ 0)."""
    s = y[X1] - y[X2] - p[DIST]
    if m[TOUCH] > 0.5:
        if s < 0.0:
            if int(p[ADH_FORM]) != ADH_PULL_OFF:
                return False
            _, raw = _contact(y, p, m)
            if raw + p[ADH_F] < 0.0:
                return False
    elif s > 0.0:
        return False
    if int(p[PRE_FORM]) == PRE_REST_STOP:
        if m[AT_STOP] > 0.5:
            fc, _ = _contact(y, p, m)
            if fc > p[PRE_W]:
                return False
        elif y[X2] < 0.0:
            return False
    if int(p[FR_FORM]) == FR_STRIBECK and m[AT_STOP] < 0.5:
        if m[STUCK] > 0.5:
            if abs(_applied(y, p, m)) > p[FR_FS]:
                return False
        elif m[SLIP_DIR] * y[V2] < 0.0:
            return False
    if int(p[LET_FORM]) != LET_NONE:
        if (y[V2] < 0.0) if m[DESC] > 0.5 else (y[V2] > 0.0):
            return False
    if int(p[BED_FORM]) == BED_LINEAR:
        pen = y[X2] - p[BED_X]
        if (pen < 0.0) if m[BED_IN] > 0.5 else (pen > 0.0):
            return False
    return True


@njit(cache=True, _nrt=False)
def _update(y: FloatArray, p: FloatArray, m: FloatArray) -> None:
    """Modes after a crossing (the state is just past it); may zero the key's speed."""
    s = y[X1] - y[X2] - p[DIST]
    if m[TOUCH] > 0.5:
        if s < 0.0:
            if int(p[ADH_FORM]) != ADH_PULL_OFF:
                m[TOUCH] = 0.0
            else:
                _, raw = _contact(y, p, m)
                if raw + p[ADH_F] < 0.0:
                    m[TOUCH] = 0.0
    elif s > 0.0:
        m[TOUCH] = 1.0
    if int(p[PRE_FORM]) == PRE_REST_STOP:
        fc, _ = _contact(y, p, m)
        if m[AT_STOP] > 0.5:
            if fc > p[PRE_W]:
                m[AT_STOP] = 0.0
        elif y[X2] < 0.0:
            # The key lands on its rail: a felt stop that does not bounce.
            y[X2] = 0.0
            y[V2] = 0.0
            m[AT_STOP] = 1.0 if fc <= p[PRE_W] else 0.0
    if int(p[FR_FORM]) == FR_STRIBECK:
        if m[AT_STOP] > 0.5:
            m[STUCK] = 1.0
            y[V2] = 0.0
        else:
            f = _applied(y, p, m)
            if m[STUCK] > 0.5:
                if abs(f) > p[FR_FS]:
                    m[STUCK] = 0.0
                    m[SLIP_DIR] = math.copysign(1.0, f)
            elif m[SLIP_DIR] * y[V2] < 0.0:
                if abs(f) <= p[FR_FS]:
                    m[STUCK] = 1.0
                    y[V2] = 0.0
                else:
                    m[SLIP_DIR] = math.copysign(1.0, f)
    if int(p[LET_FORM]) != LET_NONE:
        if y[V2] != 0.0:
            m[DESC] = 1.0 if y[V2] > 0.0 else 0.0
    if int(p[BED_FORM]) == BED_LINEAR:
        pen = y[X2] - p[BED_X]
        if pen != 0.0:
            m[BED_IN] = 1.0 if pen > 0.0 else 0.0


@njit(cache=True)
def init_modes(y: FloatArray, p: FloatArray) -> FloatArray:
    """Modes consistent with a state at rest."""
    m = np.zeros(N_MODES)
    m[SLIP_DIR] = 1.0
    m[TOUCH] = 1.0 if y[X1] - y[X2] - p[DIST] >= 0.0 else 0.0
    if int(p[PRE_FORM]) == PRE_REST_STOP and y[X2] <= 0.0:
        fc, _ = _contact(y, p, m)
        m[AT_STOP] = 1.0 if fc <= p[PRE_W] else 0.0
    if int(p[FR_FORM]) == FR_STRIBECK:
        m[STUCK] = 1.0 if abs(_applied(y, p, m)) <= p[FR_FS] and y[V2] == 0.0 else 0.0
        m[SLIP_DIR] = 1.0 if y[V2] >= 0.0 else -1.0
    m[DESC] = 1.0 if y[V2] > 0.0 else 0.0
    m[BED_IN] = 1.0 if y[X2] > p[BED_X] else 0.0
    return m


@njit(cache=True, _nrt=False)
def _rk4(
    t: float,
    y: FloatArray,
    h: float,
    p: FloatArray,
    m: FloatArray,
    moves: FloatArray,
    hint: npt.NDArray[np.int64],
    out: FloatArray,
    work: FloatArray,
    aux: FloatArray,
) -> None:
    """out = one classical RK4 step of length h from (t, y) under modes m."""
    n = y.size
    k1, k2, k3, k4, tmp = work[0], work[1], work[2], work[3], work[4]
    _rhs(t, y, p, m, moves, hint, k1, aux)
    for i in range(n):
        tmp[i] = y[i] + 0.5 * h * k1[i]
    _rhs(t + 0.5 * h, tmp, p, m, moves, hint, k2, aux)
    for i in range(n):
        tmp[i] = y[i] + 0.5 * h * k2[i]
    _rhs(t + 0.5 * h, tmp, p, m, moves, hint, k3, aux)
    for i in range(n):
        tmp[i] = y[i] + h * k3[i]
    _rhs(t + h, tmp, p, m, moves, hint, k4, aux)
    for i in range(n):
        out[i] = y[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
    if int(p[ARM_KIND]) == ARM_LAG:
        # The lagging arm's speed is algebraic: keep the state slot current for the record.
        xc, _ = _cmd(t + h, moves, hint)
        out[VA] = (xc - out[XA]) / p[ARM_TAU]
    if m[AT_STOP] > 0.5 or m[STUCK] > 0.5:
        out[V2] = 0.0


@njit(cache=True, _nrt=False)
def _record(
    t: float,
    y: FloatArray,
    p: FloatArray,
    m: FloatArray,
    moves: FloatArray,
    hint: npt.NDArray[np.int64],
    row: FloatArray,
    work: FloatArray,
    aux: FloatArray,
) -> None:
    _rhs(t, y, p, m, moves, hint, work[5], aux)
    row[OUT_T] = t
    row[OUT_XC] = aux[0]
    row[OUT_XA] = aux[1]
    row[OUT_VA] = aux[2]
    row[OUT_X1] = y[X1]
    row[OUT_V1] = y[V1]
    row[OUT_X2] = y[X2]
    row[OUT_V2] = y[V2]
    row[OUT_FC] = aux[3]
    row[OUT_F0] = aux[4]


@njit(cache=True, _nrt=False)
def _quiet(y: FloatArray, p: FloatArray, m: FloatArray, span_s: float) -> bool:
    """Whether a long step keeps RK4 accurate: no stiff element is loaded or near, and a finger
    off the key cannot reach it within the step.

    Stiff or fast elements (a stop, the let-off bump, LuGre bristles, slow Stribeck sliding)
    force short steps; otherwise the chain's fastest mode is bounded from the local slopes and
    a long step is taken only if ω·span stays below QUIET_OMEGA_H (RK4's local error ~ (ωh)⁵/120).
    """
    x2 = y[X2]
    if int(p[FR_FORM]) == FR_LUGRE:
        return False
    if int(p[FR_FORM]) == FR_STRIBECK and m[STUCK] < 0.5 and abs(y[V2]) < 3.0 * p[FR_VS]:
        return False
    if int(p[BED_FORM]) != BED_NONE and x2 > p[BED_X] - QUIET_MARGIN_M:
        return False
    if int(p[LET_FORM]) != LET_NONE and abs(x2 - p[LET_X]) < QUIET_LETOFF_M:
        return False
    s = y[X1] - x2 - p[DIST]
    k_pad = 0.0
    if m[TOUCH] > 0.5:
        k_pad = p[K1]
        form = int(p[STIFF_FORM])
        if s > 0.0 and form == STIFF_EXP:
            k_pad = p[K1] * math.exp(p[STIFF_B] * s)
        elif s > 0.0 and form == STIFF_POWER:
            k_pad = p[K1] * (1.0 + (p[STIFF_Q] + 1.0) * (s / p[STIFF_SREF]) ** p[STIFF_Q])
    else:
        closing = max(y[V1] - y[V2], 0.0)
        if s + 2.0 * closing * span_s + QUIET_GAP_M >= 0.0:
            return False
    k_key = p[K2] + k_pad
    if int(p[PRE_FORM]) == PRE_FELT and x2 < p[PRE_DELTA]:
        comp = (p[PRE_DELTA] - x2) / p[PRE_DELTA]
        k_key += 1.5 * p[PRE_W] / p[PRE_DELTA] * math.sqrt(comp)
    if int(p[ADH_FORM]) == ADH_COHESIVE:
        k_key += 3.0 * p[ADH_F] / p[ADH_RANGE]
        k_pad += 3.0 * p[ADH_F] / p[ADH_RANGE]
    omega2 = k_key / p[M2] + (p[K0] + k_pad) / p[M1]
    return omega2 * span_s * span_s < QUIET_OMEGA_H * QUIET_OMEGA_H


@njit(cache=True, _nrt=False)
def _advance(
    t: float,
    t_end: float,
    y: FloatArray,
    p: FloatArray,
    m: FloatArray,
    moves: FloatArray,
    hint: npt.NDArray[np.int64],
    breaks: FloatArray,
    bi_ref: npt.NDArray[np.int64],
    work: FloatArray,
    aux: FloatArray,
    trial: FloatArray,
    probe: FloatArray,
    counters: npt.NDArray[np.int64],
) -> None:
    """Advance y from t to t_end: substeps end on arm breakpoints and just past mode switches."""
    bi = bi_ref[0]
    nb = breaks.size
    t_cur = t
    events = 0
    while t_end - t_cur > 1e-15:
        hs = t_end - t_cur
        if bi < nb and breaks[bi] < t_end - 1e-15:
            if breaks[bi] > t_cur + 1e-15:
                hs = breaks[bi] - t_cur
            else:
                bi += 1
                continue
        _rk4(t_cur, y, hs, p, m, moves, hint, trial, work, aux)
        if _valid(trial, p, m) or events >= MAX_EVENTS_PER_STEP:
            if events >= MAX_EVENTS_PER_STEP and not _valid(trial, p, m):
                counters[1] += 1
                _update(trial, p, m)
            for i in range(y.size):
                y[i] = trial[i]
            t_cur += hs
            if bi < nb and abs(t_cur - breaks[bi]) <= 1e-15:
                bi += 1
            continue
        lo, hi = 0.0, 1.0
        while (hi - lo) * hs > BISECT_TOL_S:
            mid = 0.5 * (lo + hi)
            _rk4(t_cur, y, mid * hs, p, m, moves, hint, probe, work, aux)
            if _valid(probe, p, m):
                lo = mid
            else:
                hi = mid
        _rk4(t_cur, y, hi * hs, p, m, moves, hint, trial, work, aux)
        for i in range(y.size):
            y[i] = trial[i]
        t_cur += hi * hs
        _update(y, p, m)
        events += 1
        counters[0] += 1
    bi_ref[0] = bi


@njit(cache=True, _nrt=False)
def _hermite(a: FloatArray, b: FloatArray, w: float, span_s: float, out: FloatArray) -> None:
    """State at fraction w of a long step: cubic Hermite for positions (their speeds are states),
    linear for the rest."""
    for i in range(N_STATE):
        out[i] = (1.0 - w) * a[i] + w * b[i]
    h00 = 2.0 * w**3 - 3.0 * w**2 + 1.0
    h10 = w**3 - 2.0 * w**2 + w
    h01 = -2.0 * w**3 + 3.0 * w**2
    h11 = w**3 - w**2
    for xi, vi in ((X1, V1), (X2, V2), (XA, VA)):
        out[xi] = h00 * a[xi] + h10 * span_s * a[vi] + h01 * b[xi] + h11 * span_s * b[vi]


@njit(cache=True)
def integrate(
    y0: FloatArray,
    p: FloatArray,
    moves: FloatArray,
    breaks: FloatArray,
    t0: float,
    h: float,
    n_steps: int,
    out_every: int,
    coarse: int,
) -> tuple[FloatArray, FloatArray, npt.NDArray[np.int64]]:
    """Integrate from t0 over n_steps steps of h; record every `out_every` steps.

    While `_quiet` holds, `coarse` steps are taken as one (records inside it are interpolated
    linearly, which is exact to nanometres over half a millisecond of free flight).
    Records inside a long step are interpolated (cubic Hermite for positions).
    Returns (records [n_rec, N_OUT], final state, counters [events, unresolved, long steps]).
    """
    y = y0.copy()
    m = init_modes(y, p)
    hint = np.zeros(1, dtype=np.int64)
    work = np.zeros((6, N_STATE))
    aux = np.zeros(5)
    trial = np.zeros(N_STATE)
    probe = np.zeros(N_STATE)
    start = np.zeros(N_STATE)
    mid = np.zeros(N_STATE)
    n_rec = n_steps // out_every + 1
    rec = np.zeros((n_rec, N_OUT))
    counters = np.zeros(3, dtype=np.int64)
    bi = np.zeros(1, dtype=np.int64)
    while bi[0] < breaks.size and breaks[bi[0]] <= t0:
        bi[0] += 1
    r = 0
    k = 0
    while True:
        t = t0 + k * h
        if k % out_every == 0 and r < n_rec:
            _record(t, y, p, m, moves, hint, rec[r], work, aux)
            r += 1
        if k >= n_steps:
            break
        span = 1
        if coarse > 1 and k % coarse == 0 and k + coarse <= n_steps:
            if _quiet(y, p, m, coarse * h):
                span = coarse
        for i in range(N_STATE):
            start[i] = y[i]
        _advance(t, t0 + (k + span) * h, y, p, m, moves, hint, breaks, bi, work, aux,
                 trial, probe, counters)  # fmt: skip
        if span > 1:
            counters[2] += 1
            for j in range(1, span):
                if (k + j) % out_every == 0 and r < n_rec:
                    _hermite(start, y, j / span, span * h, mid)
                    _record(t0 + (k + j) * h, mid, p, m, moves, hint, rec[r], work, aux)
                    r += 1
        k += span
    return rec[:r], y, counters


@njit(cache=True)
def rhs_once(
    t: float, y: FloatArray, p: FloatArray, moves: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """(dy, aux) at one state with modes as at rest: for tests of signs and energy flow."""
    m = init_modes(y, p)
    m[TOUCH] = 1.0 if y[X1] - y[X2] - p[DIST] > 0.0 else 0.0
    m[STUCK] = 0.0
    m[AT_STOP] = 0.0
    m[SLIP_DIR] = 1.0 if y[V2] >= 0.0 else -1.0
    m[DESC] = 1.0 if y[V2] > 0.0 else 0.0
    m[BED_IN] = 1.0 if y[X2] > p[BED_X] else 0.0
    hint = np.zeros(1, dtype=np.int64)
    dy = np.zeros(N_STATE)
    aux = np.zeros(5)
    _rhs(t, y, p, m, moves, hint, dy, aux)
    return dy, aux
