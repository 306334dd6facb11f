"""A commanded press started in flight: the free fingertip's state before contact, in closed form.

Before the fingertip meets the key it is a mass m1 hanging from the arm on k0, c0, and the key
rests: the integrator's step (`_kernel`) is then linear in its state (fingertip position, its
half-step velocity and last acceleration, the arm's position and previous position), driven by
the arm's command, which on each phase of a moveL (accelerate, cruise, brake) is a polynomial of
time of degree two at most. So n steps of one phase are one matrix power: the state after the
first N steps comes out of a few squarings of an 8×8 matrix per phase, the same numbers as
stepping N times to within rounding, and the simulation can start at step N.

A slow press spends most of its time above the key (5 cm at 0.01 m/s: 5 s of 9), so a fit that
only reads what happens from contact on (`analysis.greybox.commanded`) simulates far fewer
steps when it starts each keystroke just before its fingertip can reach the key
(`flight_start_s`). The bound on how far the fingertip can swing from the arm is the energy
of its transients (a velocity jump v: v·√(m1/k0); an acceleration a: m1·a/k0 from equilibrium,
twice that in swing), with room to spare (`FLIGHT_SWING_FACTOR`, `CLEARANCE_M`).

Not for an arm that lags its command through a first-order filter, a finger body that yields
(`finger_hysteresis`), or a press with a fast approach: those start at rest, as always.
"""

from __future__ import annotations

import functools

import numpy as np
import numpy.typing as npt

from pianobot.physics import _kernel as K

FloatArray = npt.NDArray[np.float64]

#: Fingertip clearance above the key kept at the start, on top of the swing bound.
CLEARANCE_M = 2e-4
#: The swing bound (see the module docstring), scaled by this for safety.
FLIGHT_SWING_FACTOR = 2.0


def has_fast_approach(kp: FloatArray) -> bool:
    """Whether some of these presses (kernel columns) start with a fast approach (its down move
    starts later than 0). A fast retract comes after lift-off and does not matter here."""
    return bool(np.any(kp[:, K.T_DN] != 0.0))


def can_start_in_flight(ep: FloatArray, fast_approach: bool) -> bool:
    """Whether keystrokes with these effects (kernel effect vector) may start in flight."""
    first_order_lag = ep[K.E_LAG_FORM] == K.LAG_FIRST_ORDER and ep[K.E_LAG_S] > 0.0
    return not (first_order_lag or ep[K.E_HYST_SHARE] > 0.0 or fast_approach)


def _delay_s(ep: FloatArray) -> float:
    return float(ep[K.E_LAG_S]) if ep[K.E_LAG_FORM] == K.LAG_DELAY else 0.0


def _down_time_at(kp: FloatArray, s_m: FloatArray) -> FloatArray:
    """When each down move has covered `s_m` (its own clock; inf where it never does)."""
    a, ta, tc, vp = (kp[:, c] for c in (K.D_A, K.D_TA, K.D_TC, K.D_VP))
    s1 = 0.5 * a * ta * ta
    s2 = s1 + vp * tc
    with np.errstate(divide="ignore", invalid="ignore"):
        accel = np.sqrt(2.0 * np.maximum(s_m, 0.0) / a)
        cruise = ta + (s_m - s1) / vp
        brake = ta + tc + (vp - np.sqrt(np.maximum(vp * vp - 2.0 * a * (s_m - s2), 0.0))) / a
        out = np.where(s_m <= s1, accel, np.where(s_m <= s2, cruise, brake))
    out = np.where(s_m > s2 + vp * ta - s1, np.inf, out)  # beyond the end of the move
    return np.asarray(np.where(np.isfinite(out), out, np.inf), dtype=np.float64)


def flight_start_s(kp: FloatArray, ep: FloatArray, out_dt_s: float) -> FloatArray:
    """For kernel columns `kp` (model and commanded press, `simulate.press_columns`): the latest
    time on the output grid at which each fingertip is surely still clear of the key (0 where
    none is, or where the model cannot start in flight)."""
    n = kp.shape[0]
    if n == 0 or not can_start_in_flight(ep, has_fast_approach(kp)):
        return np.zeros(n)
    m1, k0 = kp[:, K.M1], kp[:, K.K0]
    with np.errstate(divide="ignore", invalid="ignore"):
        jump = np.where(kp[:, K.D_A] > 0.0, 0.0, kp[:, K.D_VP])  # a ramp starts at full speed
        swing = FLIGHT_SWING_FACTOR * (jump * np.sqrt(m1 / k0) + 2.0 * m1 * kp[:, K.D_A] / k0)
    reach = kp[:, K.DIST] + kp[:, K.X2S] - swing - CLEARANCE_M
    ok = np.isfinite(reach) & (reach > 0.0) & (k0 > 0.0)
    t = _down_time_at(kp, np.where(ok, reach, 0.0)) + _delay_s(ep)
    t = np.where(ok & np.isfinite(t) & (t < kp[:, K.T_UP]), t, 0.0)
    return np.asarray(np.floor(t / out_dt_s + 1e-9) * out_dt_s, dtype=np.float64)


def _step_matrices(kp: FloatArray, h: float, poly: FloatArray) -> FloatArray:
    """One integrator step as 8×8 matrices on (x1, v1, a1, x0, x0_prev, 1, s, s²), s the time
    of the arm's next command sample from the phase's origin, command α + β·s + γ·s² (`poly`)."""
    n = kp.shape[0]
    inv_m1 = 1.0 / kp[:, K.M1]
    k0, c0 = kp[:, K.K0], kp[:, K.C0]
    X1, V1, A1, X0, X0P, ONE, S, S2 = range(8)
    x0n = np.zeros((n, 8))
    x0n[:, ONE], x0n[:, S], x0n[:, S2] = poly[:, 0], poly[:, 1], poly[:, 2]
    v0 = x0n * (0.5 / h)
    v0[:, X0P] -= 0.5 / h
    v1e = np.zeros((n, 8))
    v1e[:, V1], v1e[:, A1] = 1.0, 0.5 * h
    a1 = (c0[:, None] * (v0 - v1e)) * inv_m1[:, None]
    a1[:, X0] += k0 * inv_m1
    a1[:, X1] -= k0 * inv_m1
    v1 = h * a1
    v1[:, V1] += 1.0
    m = np.zeros((n, 8, 8))
    m[:, V1] = v1
    m[:, A1] = a1
    m[:, X1] = h * v1
    m[:, X1, X1] += 1.0
    m[:, X0P, X0] = 1.0
    m[:, X0] = x0n
    m[:, ONE, ONE] = 1.0
    m[:, S, S], m[:, S, ONE] = 1.0, h
    m[:, S2, S2], m[:, S2, S], m[:, S2, ONE] = 1.0, 2.0 * h, h * h
    return m


def _power_apply(m: FloatArray, y: FloatArray, counts: npt.NDArray[np.int64]) -> FloatArray:
    """m[i]^counts[i] @ y[i] for every i (binary powers; the factors commute)."""
    y = y.copy()
    left = counts.copy()
    base = m.copy()
    while np.any(left > 0):
        odd = (left & 1).astype(bool)
        if odd.any():
            y[odd] = np.einsum("nij,nj->ni", base[odd], y[odd])
        left >>= 1
        if np.any(left > 0):
            base = base @ base
    return y


def flight_state(kp: FloatArray, ep: FloatArray, h: float, start_s: FloatArray) -> FloatArray:
    """The fingertip's (offset from the arm, half-step velocity, last acceleration) after the
    integrator's steps of `h` up to `start_s` (n, 3): columns U1S, V1S, A1S of a keystroke that
    starts there."""
    n = kp.shape[0]
    steps = np.rint(np.asarray(start_s, dtype=np.float64) / h).astype(np.int64)
    out = np.zeros((n, 3))
    if n == 0 or not np.any(steps > 0):
        return out
    delay = _delay_s(ep)
    a, ta, tc, vp = (kp[:, c] for c in (K.D_A, K.D_TA, K.D_TC, K.D_VP))
    # The down move's phases (its clock): origin, and the command from it as α + β·s + γ·s².
    s1 = 0.5 * a * ta * ta
    ends = (ta, ta + tc, 2.0 * ta + tc, np.full(n, np.inf))
    origins = (np.zeros(n), ta, ta + tc, 2.0 * ta + tc)
    polys = (
        np.stack([np.zeros(n), np.zeros(n), 0.5 * a], axis=1),
        np.stack([s1, vp, np.zeros(n)], axis=1),
        np.stack([s1 + vp * tc, vp, -0.5 * a], axis=1),
        np.stack([vp * (tc + ta), np.zeros(n), np.zeros(n)], axis=1),
    )
    y = np.zeros((n, 8))  # at rest: the samples before the move starts leave it there
    # Command sample j (1-based) is at press time j·h − delay; phase k takes the samples up to
    # its end (at a boundary both phases give the same command).
    done = np.minimum(np.floor(np.maximum(delay, 0.0) / h + 1e-9).astype(np.int64), steps)
    for end, origin, poly in zip(ends, origins, polys, strict=True):
        last = np.where(np.isfinite(end), np.floor((end + delay) / h + 1e-9), steps)
        last = np.minimum(np.maximum(last.astype(np.int64), done), steps)
        rows = np.flatnonzero(last > done)
        if rows.size:
            s = (done[rows] + 1) * h - delay - origin[rows]
            y[rows, 5], y[rows, 6], y[rows, 7] = 1.0, s, s * s
            y[rows] = _power_apply(_step_matrices(kp[rows], h, poly[rows]), y[rows],
                                   last[rows] - done[rows])
        done = last
    out[:, 0] = y[:, 0] - y[:, 3]
    out[:, 1] = y[:, 1]
    out[:, 2] = y[:, 2]
    return np.where((steps > 0)[:, None], out, 0.0)


#: What a start and its state depend on: the finger's mass, spring and damper, the down move,
#: when the up move starts, the gap to the key and where the key starts.
_INPUT_COLUMNS = [K.M1, K.K0, K.C0, K.D_A, K.D_TA, K.D_TC, K.D_VP, K.T_DN, K.T_UP, K.DIST, K.X2S]
_INPUT_EFFECTS = [K.E_LAG_FORM, K.E_LAG_S, K.E_HYST_SHARE]


def starts_in_flight(kp: FloatArray, ep: FloatArray, out_dt_s: float, h: float) -> tuple[FloatArray, FloatArray]:
    """`flight_start_s` and `flight_state` together (read-only arrays), the last answers kept:
    a fit varies the key's and the readout's parameters far more often than the finger's, and
    those leave the free flight as it was."""
    columns = np.ascontiguousarray(kp[:, _INPUT_COLUMNS], dtype=np.float64)
    effects = np.ascontiguousarray(ep[_INPUT_EFFECTS], dtype=np.float64)
    return _starts_in_flight(columns.tobytes(), effects.tobytes(), kp.shape[0], float(out_dt_s), float(h))


@functools.lru_cache(maxsize=16)
def _starts_in_flight(columns: bytes, effects: bytes, n: int, out_dt_s: float, h: float
                      ) -> tuple[FloatArray, FloatArray]:
    kp = np.zeros((n, K.N_KP))
    kp[:, _INPUT_COLUMNS] = np.frombuffer(columns, dtype=np.float64).reshape(n, len(_INPUT_COLUMNS))
    ep = np.zeros(K.N_EP)
    ep[_INPUT_EFFECTS] = np.frombuffer(effects, dtype=np.float64)
    start = flight_start_s(kp, ep, out_dt_s)
    state = flight_state(kp, ep, h, start)
    start.flags.writeable = False
    state.flags.writeable = False
    return start, state
