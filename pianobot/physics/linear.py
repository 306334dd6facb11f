"""The 2-DoF model as a linear system: state space, exact simulation, frequency response.

With the state z = [x1, ẋ1 − (c0/m1)·x0, x2, ẋ2] the model is driven by the arm position x0
alone (the shift absorbs the c0·ẋ0 term), so a piecewise-linear arm trace is simulated exactly
by a first-order-hold discretisation (`lsim_uniform`). The frequency response uses the closed
form of the two transfer functions (`_transfer`), which needs no matrix inverse per frequency.

Parameters come resolved at one vacuum level (`LinearParams`, see `msd.py`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy import linalg

from pianobot.physics.msd import LinearParams

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class StateSpace:
    """ż = A z + B u, y = C z + D u, with named states, inputs and outputs."""

    A: FloatArray
    B: FloatArray
    C: FloatArray
    D: FloatArray
    states: tuple[str, ...] = ("x1", "v1 - (c0/m1) x0", "x2", "v2")
    inputs: tuple[str, ...] = ("x0",)
    outputs: tuple[str, ...] = ("x1", "x2")

    def transfer(self, s: npt.ArrayLike) -> npt.NDArray[np.complex128]:
        """Transfer matrix C (sI − A)⁻¹ B + D at complex frequencies s: shape (..., ny, nu)."""
        s_arr = np.asarray(s, dtype=np.complex128)[..., None, None]
        n = self.A.shape[0]
        resolvent = np.linalg.solve(s_arr * np.eye(n) - self.A, self.B)
        return np.asarray(self.C @ resolvent + self.D, dtype=np.complex128)


def state_space(lp: LinearParams) -> StateSpace:
    """Forward model: arm x0 in, fingertip x1 and key x2 out.

    State z = [x1, ẋ1 − (c0/m1)·x0, x2, ẋ2]; the shift removes ẋ0 from the input.
    """
    m1, m2 = lp.m1_kg, lp.m2_kg
    k0, k1, k2 = lp.k0_npm, lp.k1_npm, lp.k2_npm
    c0, c1, c2 = lp.c0_nspm, lp.c1_nspm, lp.c2_nspm
    A = np.array(
        [
            [0.0, 1.0, 0.0, 0.0],
            [-(k0 + k1) / m1, -(c0 + c1) / m1, k1 / m1, c1 / m1],
            [0.0, 0.0, 0.0, 1.0],
            [k1 / m2, c1 / m2, -(k1 + k2) / m2, -(c1 + c2) / m2],
        ]
    )
    # ẋ1 = w + (c0/m1) x0 feeds x0 into every equation that sees ẋ1.
    B = np.array([[c0 / m1], [k0 / m1 - c0 * (c0 + c1) / m1**2], [0.0], [c0 * c1 / (m1 * m2)]])
    C = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    return StateSpace(A, B, C, np.zeros((2, 1)))


def simulate_linear(
    lp: LinearParams, t_s: npt.ArrayLike, x0_m: npt.ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Fingertip and key response to an arm trace, exact for piecewise-linear x0.

    `t_s` must be uniformly spaced; `x0_m` has shape (len(t_s),) or (n, len(t_s)) for n traces
    through the same model. The system starts at rest in equilibrium with x0 at the first sample.
    """
    ss = state_space(lp)
    y = lsim_uniform(ss, t_s, np.asarray(x0_m, dtype=np.float64)[..., None, :])
    return y[..., 0, :], y[..., 1, :]


def lsim_uniform(ss: StateSpace, t_s: npt.ArrayLike, u: npt.ArrayLike) -> FloatArray:
    """Simulate a state space on a uniform grid with linearly interpolated inputs (exact).

    Args:
        ss: the system (A may be batched: shape (..., n, n) with matching B, C, D).
        t_s: uniform times, shape (T,).
        u: inputs, shape (..., n_inputs, T), broadcast against the system batch.

    Returns:
        Outputs of shape (..., n_outputs, T). The initial state is the equilibrium for u[..., 0].
    """
    t = np.asarray(t_s, dtype=np.float64)
    u_arr = np.asarray(u, dtype=np.float64)
    if t.ndim != 1 or t.size < 2:
        raise ValueError(f"t_s should be 1-D with at least 2 samples, got shape {t.shape}.")
    dt = float(t[1] - t[0])
    if not dt > 0 or not np.allclose(np.diff(t), dt, rtol=1e-6, atol=1e-12):
        raise ValueError("t_s should be increasing and uniformly spaced.")
    if u_arr.shape[-1] != t.size:
        raise ValueError(f"inputs have {u_arr.shape[-1]} samples, t_s has {t.size}.")
    A, B, C, D = ss.A, ss.B, ss.C, ss.D
    n, m = A.shape[-1], B.shape[-1]
    batch = np.broadcast_shapes(A.shape[:-2], u_arr.shape[:-2])
    A, B = np.broadcast_to(A, (*batch, n, n)), np.broadcast_to(B, (*batch, n, m))
    u_arr = np.broadcast_to(u_arr, (*batch, m, t.size))
    # First-order hold: expm of [[A dt, B dt, 0], [0, 0, I], [0, 0, 0]] gives the exact map
    # for inputs that vary linearly between samples (the same construction scipy's lsim uses).
    M = np.zeros((*batch, n + 2 * m, n + 2 * m))
    M[..., :n, :n] = A * dt
    M[..., :n, n : n + m] = B * dt
    M[..., n : n + m, n + m :] = np.eye(m)
    E = _expm_unique(M)
    Ad = E[..., :n, :n]
    Bd1 = E[..., :n, n + m :]
    Bd0 = E[..., :n, n : n + m] - Bd1
    # Each system starts in equilibrium with its own first input; one at rest needs no solve
    # (A is singular when the chain has no static equilibrium, e.g. k0 = k2 = 0), decided per
    # system so that a row never depends on the other rows of its batch.
    u_first = u_arr[..., 0]
    displaced = np.any(u_first != 0.0, axis=-1)
    z_start = np.zeros((*batch, n))
    if np.any(displaced):
        rhs = (B[displaced] @ u_first[displaced][..., None])[..., 0]
        z_start[displaced] = -np.linalg.solve(A[displaced], rhs[..., None])[..., 0]
    # Input terms of every step at once; only the state recursion remains sequential.
    drive = Bd0 @ u_arr[..., :-1] + Bd1 @ u_arr[..., 1:]
    z = np.empty((*batch, n, t.size))
    z[..., 0] = z_start
    for k in range(1, t.size):
        z[..., k] = (Ad @ z[..., k - 1][..., None])[..., 0] + drive[..., k - 1]
    return np.asarray(C @ z + D @ u_arr, dtype=np.float64)


def _expm_unique(M: FloatArray) -> FloatArray:
    """Matrix exponential of a batch, computed once per distinct matrix (batches repeat a few
    vacuum levels many times)."""
    size = M.shape[-1]
    flat = M.reshape(-1, size * size)
    unique, inverse = np.unique(flat, axis=0, return_inverse=True)
    E = linalg.expm(unique.reshape(-1, size, size))
    return np.asarray(E[inverse.ravel()].reshape(M.shape), dtype=np.float64)


def frequency_response(
    lp: LinearParams, f_hz: npt.ArrayLike, *, output: str = "x2"
) -> tuple[FloatArray, FloatArray]:
    """Gain and unwrapped phase (rad) of x2/x0 (or x1/x0 with `output="x1"`) at `f_hz`."""
    s = 2j * np.pi * np.asarray(f_hz, dtype=np.float64)
    h = _transfer(lp, s, output)
    phase = np.angle(h)
    if phase.ndim > 0:
        phase = np.unwrap(phase)  # continuous through the resonances along the frequency axis
    return np.abs(h).astype(np.float64), np.asarray(phase, dtype=np.float64)


def peak_response(lp: LinearParams, *, output: str = "x2") -> tuple[float, float]:
    """Resonance of x2/x0 (or x1/x0): (peak_hz, peak_gain).

    Returns (0.0, static gain) when the response has no peak above DC (overdamped).
    """
    from scipy.optimize import minimize_scalar

    f = np.geomspace(1e-2, 1e4, 6001)
    gain, _ = frequency_response(lp, f, output=output)
    i = int(np.argmax(gain))
    dc_gain = float(abs(_transfer(lp, np.array(0j), output)))
    if i == 0 or gain[i] <= dc_gain:
        return 0.0, dc_gain
    lo, hi = math.log(f[max(i - 1, 0)]), math.log(f[min(i + 1, f.size - 1)])
    res = minimize_scalar(
        lambda lf: -float(abs(_transfer(lp, np.array(2j * np.pi * math.exp(lf)), output))),
        bounds=(lo, hi),
        method="bounded",
        options={"xatol": 1e-10},
    )
    return math.exp(float(res.x)), -float(res.fun)


def _transfer(lp: LinearParams, s: npt.NDArray[np.complexfloating[Any, Any]], output: str) -> Any:
    """x1/x0 and x2/x0 in closed form: a_i = k_i + c_i s are the spring-damper impedances."""
    a0 = lp.k0_npm + lp.c0_nspm * s
    a1 = lp.k1_npm + lp.c1_nspm * s
    a2 = lp.k2_npm + lp.c2_nspm * s
    key = lp.m2_kg * s**2 + a1 + a2
    den = (lp.m1_kg * s**2 + a0 + a1) * key - a1**2
    if output == "x2":
        return a0 * a1 / den
    if output == "x1":
        return a0 * key / den
    raise ValueError(f"output should be 'x1' or 'x2', got {output!r}.")
