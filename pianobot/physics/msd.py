"""The study's 2-DoF mass-spring-damper model: parameters, state space, simulation, inverse.

Equations of motion in contact (downward positive, x0 arm, x1 fingertip, x2 key):

    m1 ẍ1 = k0 (x0 − x1) − k1 (x1 − x2) + c0 (ẋ0 − ẋ1) − c1 (ẋ1 − ẋ2)
    m2 ẍ2 = k1 (x1 − x2) − k2 x2 + c1 (ẋ1 − ẋ2) − c2 ẋ2

The arm input enters through a damper (c0 ẋ0), so with the plain state [x1, ẋ1, x2, ẋ2] the
model would need ẋ0. Shifting the second state to w = ẋ1 − (c0/m1)·x0 absorbs that term: the
state space is then driven by x0 alone and a piecewise-linear arm trace is simulated exactly.

Parameters (the soft finger's stiffness grows with vacuum, k1 = 75.41 + 1.19·|p| N/m) live in
`MSDParams`; `MSDParams.at(vacuum_kpa)` resolves them to the numbers of one vacuum level.
The inverse model (key trajectory in, arm trajectory out) is a cascade of two stable
first-order filters; see `inverse_arm_trajectory`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, overload

import numpy as np
import numpy.typing as npt
from scipy import linalg

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class LinearParams:
    """Resolved model numbers at one vacuum level (SI units)."""

    m1_kg: float
    m2_kg: float
    k0_npm: float
    c0_nspm: float
    k1_npm: float
    c1_nspm: float
    k2_npm: float
    c2_nspm: float


@dataclass(frozen=True)
class MSDParams:
    """Model parameters with the study's published values as defaults.

    k1 follows the law k1 = k1_a + k1_b·|p| (p vacuum in kPa) unless `k1_table` gives identified
    values `(vacuum_kpa, k1_npm)`: at and between those levels k1 is interpolated linearly
    (levels are matched on |p|), outside them the law applies. k0 and c0 (arm–fingertip
    coupling) default to k1 and c1, as in the study's scripts.
    """

    m1_kg: float = 0.070
    m2_kg: float = 0.03405
    k1_a_npm: float = 75.41
    k1_b_npm_per_kpa: float = 1.19
    c1_nspm: float = 0.50
    k2_npm: float = 300.0  # 0.30 N/mm
    c2_nspm: float = 0.30
    k0_npm: float | None = None  # None: k0 = k1 at the same vacuum
    c0_nspm: float | None = None  # None: c0 = c1
    k1_table: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        for name in ("m1_kg", "m2_kg"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} should be > 0, got {getattr(self, name)}.")
        for name in ("c1_nspm", "k2_npm", "c2_nspm", "k0_npm", "c0_nspm"):
            value = getattr(self, name)
            if value is not None and not value >= 0.0:
                raise ValueError(f"{name} should be >= 0, got {value}.")
        table = tuple(sorted((abs(float(p)), float(k)) for p, k in self.k1_table))
        if any(k <= 0.0 for _, k in table):
            raise ValueError(f"k1_table stiffnesses should be > 0 N/m, got {self.k1_table}.")
        if len({p for p, _ in table}) != len(table):
            raise ValueError(f"k1_table has a vacuum level twice: {self.k1_table}.")
        object.__setattr__(self, "k1_table", table)

    @overload
    def k1_npm(self, vacuum_kpa: float) -> float: ...

    @overload
    def k1_npm(self, vacuum_kpa: FloatArray) -> FloatArray: ...

    def k1_npm(self, vacuum_kpa: float | FloatArray) -> float | FloatArray:
        """Finger stiffness at a vacuum level (gauge kPa; only |p| matters)."""
        p = np.abs(np.asarray(vacuum_kpa, dtype=np.float64))
        k1 = self.k1_a_npm + self.k1_b_npm_per_kpa * p
        if self.k1_table:
            levels = np.array([lv for lv, _ in self.k1_table])
            values = np.array([k for _, k in self.k1_table])
            inside = (p >= levels[0]) & (p <= levels[-1])
            k1 = np.where(inside, np.interp(p, levels, values), k1)
        if np.ndim(vacuum_kpa) == 0:
            return float(k1)
        return np.asarray(k1, dtype=np.float64)

    def at(self, vacuum_kpa: float) -> LinearParams:
        """The resolved numbers at one vacuum level."""
        k1 = self.k1_npm(float(vacuum_kpa))
        return LinearParams(
            m1_kg=self.m1_kg,
            m2_kg=self.m2_kg,
            k0_npm=k1 if self.k0_npm is None else self.k0_npm,
            c0_nspm=self.c1_nspm if self.c0_nspm is None else self.c0_nspm,
            k1_npm=k1,
            c1_nspm=self.c1_nspm,
            k2_npm=self.k2_npm,
            c2_nspm=self.c2_nspm,
        )

    def replace(self, **changes: Any) -> MSDParams:
        """A copy with some fields changed."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able dict (the table as a list of [vacuum_kpa, k1_npm] pairs)."""
        out = dataclasses.asdict(self)
        out["k1_table"] = [list(pair) for pair in self.k1_table]
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> MSDParams:
        """Inverse of `to_dict`; unknown keys raise ValueError naming them."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"unknown MSD parameter(s) {unknown}; known: {sorted(known)}.")
        values = dict(data)
        if "k1_table" in values:
            values["k1_table"] = tuple((float(p), float(k)) for p, k in values["k1_table"])
        return cls(**values)


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
    if np.any(u_arr[..., 0] != 0.0):
        z_start = -np.linalg.solve(A, B @ u_arr[..., 0][..., None])[..., 0]
    else:
        z_start = np.zeros((*batch, n))  # at rest (also when A is singular: k0 = 0)
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


def inverse_state_space(lp: LinearParams) -> StateSpace:
    """Inverse model: key x2 and its derivatives in, arm x0 and fingertip x1 out.

    X0/X2 has two more zeros than poles, so the inverse needs ẋ2 and ẍ2 as inputs; what is left
    is a cascade of two first-order low-pass filters, stable when c0, c1 > 0:

    - key equation solved for x1: (c1 s + k1) X1 = (m2 s² + (c1 + c2) s + k1 + k2) X2, i.e.
      x1 = α ẋ2 + β x2 + γ u1 with c1 u̇1 + k1 u1 = x2;
    - finger equation solved for x0: (c0 s + k0) X0 = (m1 s² + (c0+c1) s + k0+k1) X1 − (c1 s + k1) X2,
      i.e. x0 = δ ẋ1 + ε x1 − (c1/c0) x2 + u0 with c0 u̇0 + k0 u0 = ζ x1 − η x2.

    States ("u1", "u0"), inputs ("x2", "v2", "a2"), outputs ("x0", "x1").
    """
    m1, m2 = lp.m1_kg, lp.m2_kg
    k0, k1, k2 = lp.k0_npm, lp.k1_npm, lp.k2_npm
    c0, c1, c2 = lp.c0_nspm, lp.c1_nspm, lp.c2_nspm
    if not (c0 > 0.0 and c1 > 0.0 and k0 > 0.0 and k1 > 0.0):
        raise ValueError(
            f"the inverse model needs c0, c1, k0, k1 > 0 (stable filters), got c0={c0}, "
            f"c1={c1}, k0={k0}, k1={k1}."
        )
    # Polynomial division of the key equation by (c1 s + k1).
    alpha = m2 / c1
    beta = (c1 + c2 - alpha * k1) / c1
    gamma = k1 + k2 - beta * k1
    # ... and of the finger equation by (c0 s + k0).
    delta = m1 / c0
    eps = (c0 + c1 - delta * k0) / c0
    zeta = k0 + k1 - eps * k0
    eta = k1 - c1 * k0 / c0
    # x1 and ẋ1 as rows over [u1, u0 | x2, v2, a2]; u̇1 = (x2 − k1 u1)/c1.
    x1_row = np.array([gamma, 0.0, beta, alpha, 0.0])
    u1_dot = np.array([-k1 / c1, 0.0, 1.0 / c1, 0.0, 0.0])
    v1_row = gamma * u1_dot + np.array([0.0, 0.0, 0.0, beta, alpha])
    x2_row = np.array([0.0, 0.0, 1.0, 0.0, 0.0])
    u0_dot = (zeta * x1_row - eta * x2_row + np.array([0.0, -k0, 0.0, 0.0, 0.0])) / c0
    x0_row = (
        delta * v1_row + eps * x1_row - (c1 / c0) * x2_row + np.array([0.0, 1.0, 0.0, 0.0, 0.0])
    )
    dyn = np.vstack([u1_dot, u0_dot])
    out = np.vstack([x0_row, x1_row])
    return StateSpace(
        A=dyn[:, :2],
        B=dyn[:, 2:],
        C=out[:, :2],
        D=out[:, 2:],
        states=("u1", "u0"),
        inputs=("x2", "v2", "a2"),
        outputs=("x0", "x1"),
    )


def inverse_trajectories(
    lp: LinearParams,
    t_s: npt.ArrayLike,
    x2_m: npt.ArrayLike,
    *,
    v2_mps: npt.ArrayLike | None = None,
    a2_mps2: npt.ArrayLike | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Arm and fingertip trajectories (x0, x1) that make the key follow `x2_m`.

    x2 must be twice differentiable. Give its speed and acceleration when they are known
    analytically; otherwise they are taken from a cubic spline through the samples (C², so
    ẍ2 is continuous and piecewise linear, matching the exact linear-interpolation filter).
    The key is assumed at rest at the first sample (the filters start in equilibrium).
    """
    t = np.asarray(t_s, dtype=np.float64)
    x2 = np.asarray(x2_m, dtype=np.float64)
    if v2_mps is None or a2_mps2 is None:
        from scipy.interpolate import CubicSpline

        spline = CubicSpline(t, x2, axis=-1)
        v2 = spline(t, 1) if v2_mps is None else np.asarray(v2_mps, dtype=np.float64)
        a2 = spline(t, 2) if a2_mps2 is None else np.asarray(a2_mps2, dtype=np.float64)
    else:
        v2, a2 = np.asarray(v2_mps, dtype=np.float64), np.asarray(a2_mps2, dtype=np.float64)
    u = np.stack(np.broadcast_arrays(x2, v2, a2), axis=-2)
    y = lsim_uniform(inverse_state_space(lp), t, u)
    return y[..., 0, :], y[..., 1, :]


def inverse_arm_trajectory(
    lp: LinearParams,
    t_s: npt.ArrayLike,
    x2_m: npt.ArrayLike,
    *,
    v2_mps: npt.ArrayLike | None = None,
    a2_mps2: npt.ArrayLike | None = None,
) -> FloatArray:
    """Arm trajectory x0(t) that makes the key follow `x2_m` (see `inverse_trajectories`)."""
    return inverse_trajectories(lp, t_s, x2_m, v2_mps=v2_mps, a2_mps2=a2_mps2)[0]


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


def static_deformation_ratio(lp: LinearParams) -> float:
    """The model's static ratio r* = Δx1/Δx2 = (k1 + k2)/k1 (the key spring loads the finger)."""
    return (lp.k1_npm + lp.k2_npm) / lp.k1_npm


def deformation_ratio(
    x1_static_m: npt.ArrayLike,
    x1_initial_m: npt.ArrayLike,
    x2_static_m: npt.ArrayLike,
    x2_initial_m: npt.ArrayLike,
) -> FloatArray:
    """Measured static deformation ratio r = (x1^S − x1^I)/(x2^S − x2^I) (NaN if the key did not move)."""
    dx1 = np.asarray(x1_static_m, dtype=np.float64) - np.asarray(x1_initial_m, dtype=np.float64)
    dx2 = np.asarray(x2_static_m, dtype=np.float64) - np.asarray(x2_initial_m, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(dx2 != 0.0, dx1 / np.where(dx2 != 0.0, dx2, 1.0), np.nan)
    return np.asarray(r, dtype=np.float64)


def error_rate(r_gt: npt.ArrayLike, r_star: npt.ArrayLike) -> FloatArray:
    """The study's error rate σ = |r_gt − r*| / r* of a measured against a model ratio."""
    gt = np.asarray(r_gt, dtype=np.float64)
    star = np.asarray(r_star, dtype=np.float64)
    return np.asarray(np.abs(gt - star) / star, dtype=np.float64)
