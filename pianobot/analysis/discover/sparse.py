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
