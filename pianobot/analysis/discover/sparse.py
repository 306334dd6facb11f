"""Sparse regression (SINDy-style STLSQ) over candidate force terms, used to *propose* effects.

Discovery never accepts a sparse term directly: the terms it selects only point at effect
families of the vocabulary, which are then refit by simulation error like every other candidate.
That keeps the decision in one place (information criterion + held-out gap) and keeps a noisy
differentiated force signal from ever becoming part of a model.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class KeyState:
    """States along measured keystrokes, all arrays of one length (SI units, downward positive)."""

    x2_m: FloatArray  # key position
    v2_mps: FloatArray  # key velocity
    compression_m: FloatArray  # finger compression x1 - x2 - distance (> 0 in contact)
    contact_force_n: FloatArray  # model's finger-on-key force (negative = would pull)
    descending: FloatArray  # 1.0 where the arm moves down, else 0.0


@dataclass(frozen=True)
class Term:
    """One library column: a name, the effect family it points at, and how to evaluate it."""

    name: str
    family: str | None  # an effect of the vocabulary, or None for plain polynomial terms
    evaluate: Callable[[KeyState], FloatArray]


def _hinge(c_m: float) -> Callable[[KeyState], FloatArray]:
    return lambda s: np.maximum(0.0, s.x2_m - c_m)


def _tanh(v0_mps: float) -> Callable[[KeyState], FloatArray]:
    return lambda s: np.tanh(s.v2_mps / v0_mps)


def _bump(c_m: float, width_m: float) -> Callable[[KeyState], FloatArray]:
    # Letoff acts only while descending, as a bump around a depth near the bottom of travel.
    return lambda s: s.descending * np.exp(-0.5 * ((s.x2_m - c_m) / width_m) ** 2)


def term_library(key_dip_m: float = 0.010) -> tuple[Term, ...]:
    """The candidate force terms: polynomials, velocity signs, hinges, contact-sign indicators.

    Hinge and bump centres are spread over the key's travel so that an end stop or escapement
    anywhere in the lower half of the dip has a term close to it.
    """
    terms: list[Term] = [
        Term("1", "key_preload", lambda s: np.ones_like(s.x2_m)),
        Term("x2", None, lambda s: s.x2_m),
        Term("x2^2", None, lambda s: s.x2_m**2),
        Term("x2^3", None, lambda s: s.x2_m**3),
        Term("v2", None, lambda s: s.v2_mps),
        Term("sign(v2)", "key_friction", lambda s: np.sign(s.v2_mps)),
        Term("tanh(v2/5mm/s)", "key_friction", _tanh(0.005)),
        Term("compression^2", "finger_stiffening", lambda s: np.maximum(s.compression_m, 0.0) ** 2),
        Term("compression^3", "finger_stiffening", lambda s: np.maximum(s.compression_m, 0.0) ** 3),
        Term(
            "[contact force < 0]",
            "adhesion",
            lambda s: (s.contact_force_n < 0.0).astype(np.float64),
        ),
    ]
    for fraction in (0.5, 0.6, 0.7, 0.8, 0.9):
        c_m = fraction * key_dip_m
        terms.append(Term(f"max(0, x2 - {c_m * 1e3:.1f} mm)", "keybed", _hinge(c_m)))
    for fraction in (0.6, 0.75, 0.9):
        c_m = fraction * key_dip_m
        terms.append(
            Term(f"bump(x2 ~ {c_m * 1e3:.1f} mm, down)", "letoff", _bump(c_m, 0.1 * key_dip_m))
        )
    return tuple(terms)


def evaluate_library(terms: tuple[Term, ...], state: KeyState) -> FloatArray:
    """The library matrix Theta (n samples x p terms)."""
    return np.column_stack([np.asarray(t.evaluate(state), dtype=np.float64) for t in terms])


def stlsq(
    theta: FloatArray,
    y: FloatArray,
    threshold: float = 0.1,
    ridge: float = 1e-6,
    max_iter: int = 20,
) -> FloatArray:
    """Sequentially thresholded least squares on column-normalised features.

    Columns are scaled to unit RMS so one threshold applies to every term; a coefficient is
    dropped when its contribution is below `threshold` times the RMS of the target.

    Returns:
        Coefficients in the original (unscaled) units of `theta`; zeros for dropped terms.
    """
    n, p = theta.shape
    if y.shape != (n,):
        raise ValueError(f"target length {y.shape} does not match library rows {n}")
    scale = np.sqrt(np.mean(theta**2, axis=0))
    usable = scale > 0
    scale = np.where(usable, scale, 1.0)
    z = theta / scale
    y_rms = float(np.sqrt(np.mean(y**2))) or 1.0
    active = usable.copy()
    xi = np.zeros(p)
    for _ in range(max_iter):
        xi = np.zeros(p)
        if not active.any():
            break
        za = z[:, active]
        xi[active] = np.linalg.solve(za.T @ za + ridge * n * np.eye(za.shape[1]), za.T @ y)
        keep = active & (np.abs(xi) >= threshold * y_rms)
        if np.array_equal(keep, active):
            break
        active = keep
    xi[~active] = 0.0
    return xi / scale


@dataclass(frozen=True)
class Proposal:
    """A term STLSQ kept, with its share of the explained residual force."""

    term: str
    family: str | None
    coefficient: float
    share: float  # fraction of the fitted residual's RMS this term carries


def propose_terms(
    state: KeyState,
    residual_force_n: FloatArray,
    key_dip_m: float = 0.010,
    threshold: float = 0.1,
) -> tuple[Proposal, ...]:
    """Run STLSQ on the residual key force and list the kept terms, largest share first."""
    finite = np.isfinite(residual_force_n)
    for array in (state.x2_m, state.v2_mps, state.compression_m, state.contact_force_n):
        finite &= np.isfinite(array)
    if finite.sum() < 10:
        return ()
    masked = KeyState(
        state.x2_m[finite],
        state.v2_mps[finite],
        state.compression_m[finite],
        state.contact_force_n[finite],
        state.descending[finite],
    )
    terms = term_library(key_dip_m)
    theta = evaluate_library(terms, masked)
    y = residual_force_n[finite]
    xi = stlsq(theta, y, threshold=threshold)
    contributions = np.sqrt(np.mean((theta * xi) ** 2, axis=0))
    total = float(contributions.sum()) or 1.0
    kept = [
        Proposal(t.name, t.family, float(c), float(s / total))
        for t, c, s in zip(terms, xi, contributions, strict=True)
        if c != 0.0
    ]
    return tuple(sorted(kept, key=lambda p: -p.share))


def proposed_families(proposals: tuple[Proposal, ...], min_share: float = 0.1) -> tuple[str, ...]:
    """Effect families named by the kept terms, in order of their share, without repeats."""
    families: list[str] = []
    for proposal in proposals:
        if proposal.family and proposal.share >= min_share and proposal.family not in families:
            families.append(proposal.family)
    return tuple(families)


# ---- the residual search over a fitted model ----------------------------------------------------


def _second_derivative(t: FloatArray, x: FloatArray) -> FloatArray:
    from scipy.signal import savgol_filter

    ok = np.isfinite(x)
    if ok.sum() < 11:
        return np.full_like(x, np.nan)
    filled = np.interp(t, t[ok], x[ok])
    acc = np.asarray(savgol_filter(filled, 9, 3, deriv=2, delta=float(np.median(np.diff(t)))), dtype=np.float64)
    acc[~ok] = np.nan
    return acc


def trajectory_proposals(t_s: FloatArray, x0_m: FloatArray, x1_m: FloatArray, x2_m: FloatArray,
                         distance_m: FloatArray, model_x1_m: FloatArray, model_x2_m: FloatArray,
                         model_v2_mps: FloatArray, model_force_n: FloatArray, m2_kg: float) -> tuple[Proposal, ...]:
    """STLSQ on the key force the model lacks, m2·(ẍ2 measured − ẍ2 model), over the model's
    states along the keystrokes (rows; NaN where not modelled)."""
    force, x2, v2, comp, fc, down = [], [], [], [], [], []
    for i in range(x2_m.shape[0]):
        t = t_s[i] if t_s.ndim == 2 else t_s
        ok = np.isfinite(model_x2_m[i])
        if ok.sum() < 11:
            continue
        measured = np.where(ok, x2_m[i], np.nan)
        force.append(m2_kg * (_second_derivative(t, measured) - _second_derivative(t, np.where(ok, model_x2_m[i], np.nan))))
        x2.append(model_x2_m[i])
        v2.append(model_v2_mps[i])
        comp.append(model_x1_m[i] - model_x2_m[i] - distance_m[i])
        fc.append(model_force_n[i])
        down.append((np.gradient(x0_m[i], t) > 0).astype(np.float64))
    if not force:
        return ()
    state = KeyState(*(np.concatenate(a) for a in (x2, v2, comp, fc, down)))
    return propose_terms(state, np.concatenate(force), key_dip_m=float(np.nanmax(np.concatenate(x2))) or 0.010)


def outcome_proposals(speed_mps: FloatArray, acceleration_mps2: FloatArray, depth_m: FloatArray,
                      vacuum_kpa: FloatArray, residual: FloatArray, threshold: float = 0.1) -> tuple[Proposal, ...]:
    """STLSQ of an outcome residual (e.g. on-velocity, model − measured) over the press
    parameters: powers of speed point at the piano's velocity map, the trapezoid's cap
    min(v, √(a·d)) at the arm's acceleration, depth at an end stop, vacuum at the finger."""
    ok = np.isfinite(residual) & np.isfinite(speed_mps) & np.isfinite(depth_m)
    if ok.sum() < 8:
        return ()
    v, a, d, p, y = speed_mps[ok], acceleration_mps2[ok], depth_m[ok], np.abs(vacuum_kpa[ok]), residual[ok]
    a = np.where(np.isfinite(a), a, np.nanmedian(a) if np.isfinite(a).any() else 1.0)
    cap = np.minimum(v, np.sqrt(a * np.maximum(d, 1e-4)))
    columns = [("1", None, np.ones_like(v)), ("v", None, v), ("v^2", "velocity_curve", v**2),
               ("v^3", "velocity_curve", v**3), ("sqrt(v)", "velocity_curve", np.sqrt(v)),
               ("min(v, sqrt(a d)) - v", "arm_acceleration", cap - v), ("1/a", "arm_acceleration", 1.0 / a),
               ("depth", "keybed", d), ("|p|", "finger_stiffening", p), ("v |p|", "finger_stiffening", v * p)]
    theta = np.column_stack([c for _, _, c in columns])
    xi = stlsq(theta, y, threshold=threshold)
    contributions = np.sqrt(np.mean((theta * xi) ** 2, axis=0))
    total = float(contributions.sum()) or 1.0
    kept = [Proposal(name, family, float(c), float(s / total))
            for (name, family, _), c, s in zip(columns, xi, contributions, strict=True) if c != 0.0 and name != "1"]
    return tuple(sorted(kept, key=lambda q: -q.share))
