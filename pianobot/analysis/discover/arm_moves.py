"""The measured arm's down moves fitted as moveL trapezoids, all keystrokes at once.

`arm_acceleration` scans some forty accelerations and fits every keystroke's down move at each
(travel, speed and start free, the acceleration shared): about a thousand three-parameter fits
per take. One `scipy.optimize.least_squares` call per move spent ~10 ms in Python overhead and
finite differences for work of ~0.1 ms, most of a take's discovery time. Here the moves are
padded into one array and fitted together by a bounded Levenberg–Marquardt iteration with the
trapezoid's exact derivatives: each iteration is a handful of array operations and one batch of
3×3 solves, and each move keeps its own damping and stops on its own.

The trapezoid (acceleration a, cruise speed v, travel d, start t0; τ = t − t0):

    s = ½aτ²                 for 0 ≤ τ < v/a                (accelerating)
    s = vτ − v²/(2a)         for v/a ≤ τ < d/v              (cruising)
    s = d − ½a(T − τ)²       for d/v ≤ τ < T = d/v + v/a    (braking)
    s = d                    after

a triangle (d < v²/a) peaks at √(a·d) at τ = √(d/a) and never cruises; a = ∞ is the ramp
s = clip(vτ, 0, d).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

#: Give up on a move whose damping grew this large without an improving step (a minimum).
_MAX_DAMPING = 1e12
#: A move has converged when an accepted step lowers its cost by less than this fraction.
_FTOL = 1e-10


@dataclass(frozen=True)
class DownMoves:
    """Down moves padded to one length: times, positions, which samples are real, and each
    move's start values and bounds (travel, speed, start)."""

    t: FloatArray  # (m, L): each move's times, padded with its last time
    x: FloatArray  # (m, L): its positions, padded with its last position
    real: FloatArray  # (m, L): 1 for a sample, 0 for padding
    p0: FloatArray  # (m, 3): travel, speed, start
    lo: FloatArray  # (m, 3)
    hi: FloatArray  # (m, 3)

    @classmethod
    def of(cls, moves: list[tuple[FloatArray, FloatArray]]) -> DownMoves:
        """The moves (times, positions), each with start values read off its own trace."""
        m, length = len(moves), max(t.size for t, _ in moves)
        t_pad, x_pad, real = np.zeros((m, length)), np.zeros((m, length)), np.zeros((m, length))
        p0, lo, hi = np.zeros((m, 3)), np.zeros((m, 3)), np.zeros((m, 3))
        for k, (t, x) in enumerate(moves):
            t_pad[k, : t.size], t_pad[k, t.size :] = t, t[-1]
            x_pad[k, : x.size], x_pad[k, x.size :] = x, x[-1]
            real[k, : t.size] = 1.0
            d0 = float(np.max(x))
            moving = np.flatnonzero((x > 0.1 * d0) & (x < 0.9 * d0))
            v0 = 0.8 * d0 / max(float(t[moving[-1]] - t[moving[0]]), 1e-3) if moving.size > 1 else 0.05
            t0 = float(t[np.flatnonzero(x > 0.02 * d0)[0]]) - 0.5 * d0 * 0.02 / max(v0, 1e-3)
            lo[k] = (0.5 * d0, 1e-3, t[0] - 0.5)
            hi[k] = (1.5 * d0, 5.0, t[-1])
            p0[k] = np.clip((d0, v0, t0), lo[k] + 1e-9, hi[k] - 1e-9)
        return cls(t_pad, x_pad, real, p0, lo, hi)

    def residuals(self, r: FloatArray) -> list[FloatArray]:
        """A (m, L) residual as each move's own samples, in order."""
        return [row[mask > 0] for row, mask in zip(r, self.real, strict=True)]


@dataclass(frozen=True)
class MoveFit:
    """The moves fitted at one acceleration."""

    params: FloatArray  # (m, 3): travel, speed, start
    residual: FloatArray  # (m, L): model − measured, 0 on padding
    rss: float  # over every real sample

    @property
    def starts(self) -> FloatArray:
        return self.params[:, 2]


def ramp_and_duration_s(d: FloatArray, v: FloatArray, a: float) -> tuple[FloatArray, FloatArray]:
    """Time spent accelerating (= braking) and the whole move's duration, for travels `d` and
    cruise speeds `v` at acceleration `a` (finite): a triangle when d < v²/a."""
    triangle = d < v * v / a
    ta = np.where(triangle, np.sqrt(d / a), v / a)
    total = np.where(triangle, 2.0 * ta, d / v + v / a)
    return np.asarray(ta, dtype=np.float64), np.asarray(total, dtype=np.float64)


def _phases(t: FloatArray, params: FloatArray, a: float) -> tuple[FloatArray, ...]:
    """τ, travel and speed as columns, whether a triangle (1.0), the time spent accelerating
    (= braking) and the move's duration (finite `a`)."""
    d, v, t0 = (params[:, j : j + 1] for j in range(3))
    ta, total = ramp_and_duration_s(d, v, a)
    triangle = np.asarray(d < v * v / a, dtype=np.float64)
    return tuple(np.asarray(z, dtype=np.float64) for z in (t - t0, d, v, triangle, ta, total))


def trapezoid_m(t: FloatArray, params: FloatArray, a: float) -> FloatArray:
    """Distance moved at times `t` (m, L) by moves `params` (m, 3: travel, speed, start) at
    acceleration `a` (∞: a ramp)."""
    if not math.isfinite(a):
        d, v, t0 = (params[:, j : j + 1] for j in range(3))
        return np.asarray(np.clip(v * (t - t0), 0.0, d), dtype=np.float64)
    tau, d, v, triangle_f, ta, total = _phases(t, params, a)
    triangle = triangle_f > 0.0
    peak = np.where(triangle, a * ta, v)
    up = np.clip(tau, 0.0, ta)
    down = np.clip(tau - (total - ta), 0.0, ta)
    # Accelerate, cruise (none for a triangle), brake: ½a·u² + peak·(τ − ta) − ½a·w² in effect.
    cruise = np.clip(tau, ta, total) - ta
    return np.asarray(0.5 * a * up * up + peak * cruise - 0.5 * a * down * down, dtype=np.float64)


def trapezoid(t: FloatArray, params: FloatArray, a: float) -> tuple[FloatArray, FloatArray]:
    """`trapezoid_m` and its derivatives (m, L, 3) with respect to the params."""
    jac = np.zeros((*t.shape, 3))
    if not math.isfinite(a):
        d, v, t0 = (params[:, j : j + 1] for j in range(3))
        tau = t - t0
        moving = (tau > 0.0) & (v * tau < d)
        jac[..., 0] = (tau > 0.0) & ~moving
        jac[..., 1] = np.where(moving, tau, 0.0)
        jac[..., 2] = np.where(moving, -v, 0.0)
        return trapezoid_m(t, params, a), jac
    tau, d, v, triangle_f, ta, total = _phases(t, params, a)
    triangle = triangle_f > 0.0
    left = total - tau  # time to the end of the move
    up = (tau >= 0.0) & (tau < ta)
    cruise = (tau >= ta) & (tau < total - ta)
    down = (tau >= total - ta) & (tau < total)
    done = tau >= total
    # d: only where braking (the end moves with it) and after; v: cruising and braking of a
    # trapezoid (a triangle's peak is set by d and a); t0: the speed, negated.
    dd_brake = np.where(triangle, 1.0 - left / ta, 1.0 - a * left / v)
    jac[..., 0] = np.where(down, dd_brake, np.where(done, 1.0, 0.0))
    dv_brake = np.where(triangle, 0.0, -a * left * (1.0 / a - d / (v * v)))
    jac[..., 1] = np.where(cruise, np.where(triangle, 0.0, tau - v / a), np.where(down, dv_brake, 0.0))
    jac[..., 2] = np.select([up, cruise, down], [-a * tau, np.broadcast_to(-v, t.shape), -a * left], 0.0)
    return trapezoid_m(t, params, a), jac


def fit_moves(moves: DownMoves, a: float, max_iterations: int = 200) -> MoveFit:
    """Every move's travel, speed and start at acceleration `a`, least squares within bounds
    (Levenberg–Marquardt with Marquardt's scaling, steps clipped to the bounds, one damping
    per move; each iteration works on the moves still improving)."""

    def evaluate(rows: npt.NDArray[np.intp], params: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        s, jac = trapezoid(moves.t[rows], params, a)
        real = moves.real[rows]
        r = (s - moves.x[rows]) * real
        return r, jac * real[..., None], np.sum(r * r, axis=1)

    everyone = np.arange(moves.p0.shape[0])
    p = moves.p0.copy()
    r, jac, cost = evaluate(everyone, p)
    damping = np.full(everyone.size, 1e-3)
    active = np.ones(everyone.size, dtype=bool)
    eye = np.eye(3)
    for _ in range(max_iterations):
        rows = np.flatnonzero(active)
        if rows.size == 0:
            break
        g = np.einsum("mlk,ml->mk", jac[rows], r[rows])
        h = np.einsum("mlk,mlj->mkj", jac[rows], jac[rows])
        diag = np.diagonal(h, axis1=1, axis2=2)
        floor = 1e-12 * np.max(diag, axis=1, keepdims=True) + 1e-300
        system = h + (damping[rows, None] * np.maximum(diag, floor))[:, :, None] * eye
        step = -np.linalg.solve(system, g[..., None])[..., 0]
        trial = np.clip(p[rows] + step, moves.lo[rows], moves.hi[rows])
        r_new, jac_new, cost_new = evaluate(rows, trial)
        better = cost_new < cost[rows]
        took = rows[better]
        converged = cost[took] - cost_new[better] <= _FTOL * cost[took]
        p[took], r[took], jac[took], cost[took] = trial[better], r_new[better], jac_new[better], cost_new[better]
        damping[rows] = np.where(better, damping[rows] / 3.0, damping[rows] * 4.0)
        active[took[converged]] = False
        active &= (damping < _MAX_DAMPING) & (cost > 0.0)
    return MoveFit(p, r, float(np.sum(cost)))
