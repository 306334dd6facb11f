"""The inverse of the 2-DoF model: the arm (and fingertip) motion that makes the key follow a
desired trajectory, as a cascade of two stable first-order filters (see `inverse_state_space`).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from pianobot.physics.linear import StateSpace, lsim_uniform
from pianobot.physics.msd import LinearParams

FloatArray = npt.NDArray[np.float64]


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
