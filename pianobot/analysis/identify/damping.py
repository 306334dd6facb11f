"""Damping cross-check by logarithmic decrement of the key's free ringing.

While the arm stands still (a hold at the bottom, or after the press), whatever the key does is
the free response of the finger–key system: a decaying oscillation. For a mode with damping ratio ζ the
amplitude falls by the same factor every cycle, δ = ln(A_i / A_{i+1}) = 2πζ / √(1 − ζ²), so
ζ = δ / √(4π² + δ²), and the cycle length gives the damped frequency f_d. This needs no model
and no fit of the press itself, so it checks the dampings the trajectory fit identified: the
identified model's mode nearest f_d (an eigenvalue of its A matrix with the arm held still)
should have a similar ζ.

Successive extrema of both signs are used (half-cycles, δ = 2·the decay per half-cycle); only
extrema clearly above the noise count (`min_amplitude_m` or 5× the noise σ), and a keystroke
needs at least `MIN_EXTREMA` of them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.analysis.greybox.noise import noise_sigma_m
from pianobot.physics.linear import state_space
from pianobot.physics.msd import MSDParams

FloatArray = npt.NDArray[np.float64]
MIN_EXTREMA = 4
#: The arm counts as stopped once within this fraction of its travel from its final level.
ARM_SETTLED_FRACTION = 0.01
#: A still period shorter than this holds too few cycles of the key's 7-20 Hz ringing.
MIN_FREE_S = 0.15


@dataclass(frozen=True)
class Ringing:
    """Free-ringing decay of one keystroke."""

    trial_id: str
    vacuum_kpa: float
    frequency_hz: float
    zeta: float
    n_extrema: int


@dataclass(frozen=True)
class DampingCheck:
    """Log-decrement estimates pooled over keystrokes, beside the identified model's mode."""

    ringing: tuple[Ringing, ...]
    frequency_hz: float  # median over keystrokes
    zeta: float  # median over keystrokes
    zeta_ci95: tuple[float, float]  # 2.5–97.5 % of a bootstrap of the median over keystrokes
    model_frequency_hz: float  # identified model's mode nearest frequency_hz
    model_zeta: float

    def to_dict(self) -> dict[str, object]:
        """Plain values for JSON and the model file."""
        return {
            "method": "logarithmic decrement of free key ringing after the arm stops",
            "n_keystrokes": len(self.ringing), "frequency_hz": self.frequency_hz, "zeta": self.zeta,
            "zeta_ci95": list(self.zeta_ci95), "model_frequency_hz": self.model_frequency_hz,
            "model_zeta": self.model_zeta,
        }


def _extrema(x: FloatArray) -> npt.NDArray[np.intp]:
    """Indices of strict local extrema (sign changes of the first difference)."""
    d = np.diff(x)
    turn = np.flatnonzero(np.sign(d[1:]) * np.sign(d[:-1]) < 0) + 1
    return np.asarray(turn, dtype=np.intp)


def _refine(t: FloatArray, x: FloatArray, idx: npt.NDArray[np.intp]) -> tuple[FloatArray, FloatArray]:
    """Time and |amplitude| of each extremum from a parabola through it and its neighbours.

    At 120 frames/s a 10 Hz ringing has 12 samples per cycle: the sampled maximum misses the
    true peak time by up to half a frame, which would bias the period by several per cent.
    """
    lo, hi = np.clip(idx - 1, 0, x.size - 1), np.clip(idx + 1, 0, x.size - 1)
    y0, y1, y2 = x[lo], x[idx], x[hi]
    den = y0 - 2.0 * y1 + y2
    shift = np.where(np.abs(den) > 1e-300, 0.5 * (y0 - y2) / np.where(den == 0, 1.0, den), 0.0)
    shift = np.clip(shift, -0.5, 0.5)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    return t[idx] + shift * dt, np.abs(y1 - 0.25 * (y0 - y2) * shift)


def log_decrement(t_s: FloatArray, x_m: FloatArray, *, min_amplitude_m: float) -> tuple[float, float, int]:
    """(damped frequency Hz, ζ, extrema used) of a free decaying oscillation; NaNs if too short.

    `x_m` should start after the excitation ended; its final level is taken as the rest level.
    """
    ok = np.isfinite(x_m)
    t, x = t_s[ok], x_m[ok]
    nan = float("nan")
    if x.size < 8:
        return nan, nan, 0
    x = x - float(np.median(x[-max(x.size // 4, 3) :]))
    idx = _extrema(x)
    amp = np.abs(x[idx])
    # Keep the run of alternating-sign extrema above the noise, from the first one.
    keep: list[int] = []
    for i, a in zip(idx, amp, strict=True):
        if a < min_amplitude_m:
            break
        if keep and np.sign(x[i]) == np.sign(x[keep[-1]]):
            if abs(x[i]) > abs(x[keep[-1]]):
                keep[-1] = int(i)  # a noise wiggle near a peak: keep the larger
            continue
        keep.append(int(i))
    if len(keep) < MIN_EXTREMA:
        return nan, nan, len(keep)
    t_ext, a = _refine(t, x, np.asarray(keep, dtype=np.intp))
    half_cycles = np.arange(len(keep), dtype=np.float64)
    slope = float(np.polyfit(half_cycles, np.log(a), 1)[0])
    delta = -2.0 * slope  # per full cycle
    period = 2.0 * float(np.median(np.diff(t_ext)))
    if not (delta > 0 and period > 0):
        return nan, nan, len(keep)
    return 1.0 / period, delta / math.sqrt(4.0 * math.pi**2 + delta**2), len(keep)


def model_modes(params: MSDParams, vacuum_kpa: float) -> list[tuple[float, float]]:
    """(damped frequency Hz, ζ) of each oscillating mode with the arm held still."""
    eig = np.linalg.eigvals(state_space(params.at(vacuum_kpa)).A)
    modes = []
    for lam in eig[np.imag(eig) > 0]:
        wn = abs(lam)
        modes.append((float(np.imag(lam)) / (2 * math.pi), float(-np.real(lam) / wn)))
    return modes


def _still_runs(x0: FloatArray, min_samples: int) -> list[tuple[int, int]]:
    """(start, end) index ranges where the arm stands still for at least `min_samples` samples.

    Still: each step smaller than the larger of 6 noise σ and `ARM_SETTLED_FRACTION` of the
    travel per 100 samples (a moving arm covers that in a few frames), and the run stays within
    `ARM_SETTLED_FRACTION` of the travel of its final level.
    """
    travel = float(np.nanmax(x0) - np.nanmin(x0))
    if not travel > 0:
        return []
    step_tol = max(6.0 * noise_sigma_m(x0), 0.01 * ARM_SETTLED_FRACTION * travel)
    still = np.r_[False, np.abs(np.diff(x0)) < step_tol]
    runs: list[tuple[int, int]] = []
    edges = np.flatnonzero(np.diff(np.r_[0, still.astype(np.int8), 0]))
    for start, end in zip(edges[::2], edges[1::2], strict=True):
        level = x0[end - 1]
        inside = np.flatnonzero(np.abs(x0[start:end] - level) <= ARM_SETTLED_FRACTION * travel)
        if inside.size:
            start = start + int(inside[0])
        if end - start >= min_samples:
            runs.append((int(start), int(end)))
    return runs


def damping_check(batch: KeystrokeBatch, params: MSDParams, *, seed: int = 0) -> DampingCheck | None:
    """Log decrement of the key (x2) while the arm stands still; None if it never rings there.

    The arm stands still during a hold at the bottom (the key rings under the finger) and
    after the keystroke (a finger still on the key, as in the study's takes, keeps it ringing;
    one that has left it leaves a key at rest). Of a keystroke's still periods the one with the
    longest measurable decay is used.
    """
    noise = noise_sigma_m(batch.x2_m)
    dt = batch.dt_s
    min_samples = max(8, int(round(MIN_FREE_S / dt))) if dt > 0 else 8
    found: list[Ringing] = []
    for i in range(batch.n):
        t = batch.row_times_s(i)
        best: tuple[float, float, int] | None = None
        for start, end in _still_runs(batch.x0_m[i], min_samples):
            x2 = batch.x2_m[i, start:end]
            if not np.isfinite(x2).any():
                continue
            peak = float(np.nanmax(np.abs(x2 - np.nanmedian(x2))))
            f, zeta, n = log_decrement(t[start:end], x2, min_amplitude_m=max(5.0 * noise, 0.05 * peak))
            if math.isfinite(zeta) and (best is None or n > best[2]):
                best = (f, zeta, n)
        if best is not None:
            found.append(Ringing(batch.trial_id[i], float(batch.vacuum_kpa[i]), *best))
    if not found:
        return None
    freq = float(np.median([r.frequency_hz for r in found]))
    zetas = np.array([r.zeta for r in found])
    rng = np.random.default_rng(seed)
    boots = [float(np.median(rng.choice(zetas, zetas.size))) for _ in range(200)]
    level = float(np.median([r.vacuum_kpa for r in found]))
    modes = model_modes(params, level)
    f_model, z_model = min(modes, key=lambda m: abs(m[0] - freq)) if modes else (float("nan"), float("nan"))
    return DampingCheck(tuple(found), freq, float(np.median(zetas)),
                        (float(np.percentile(boots, 2.5)), float(np.percentile(boots, 97.5))),
                        f_model, z_model)
