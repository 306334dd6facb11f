"""Static finger stiffness from force-sensor presses (the study's method) and its vacuum law.

The finger is pressed onto a force sensor by a fixed compression at each vacuum level; the
stiffness is the press force divided by that compression (the study used 13.9 mm for every
level), averaged over the presses of a level; then k1(p) = a + b·|p| is fitted by least squares
with a 95 % interval from the fit's covariance.

Force logs are read and split into presses by `pianobot.io.force_log.read_force_log`. The
press force is taken as

- the peak of the force smoothed over `SMOOTH_SAMPLES` samples (≈ 60 ms at 47.8 Hz): the sensor
  reads in steps of 0.035 N with ±2–3 steps of noise, so a single-sample maximum is biased
  upwards by the noise, more so the longer the press;
- above the log's resting baseline: the calibration's 0.204 N offset is what the sensor reads
  with nothing on it, not force from the finger.

On the study's logs this gives k1 ≈ 67 + 1.42·|p| N/m (95 % CI of a: 56–79, of b: 1.18–1.66), not the published 75.41 + 1.19·|p| (see
`PUBLISHED_LAW`); the stiffness also saturates above −50 kPa, so a straight line is a coarse
summary (`StaticStiffness.residual_npm` shows how coarse).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from pianobot.analysis.greybox.covariance import Z95
from pianobot.errors import InputError
from pianobot.io.force_log import ForceCalibration, ForceLog, read_force_log

FloatArray = npt.NDArray[np.float64]
STUDY_COMPRESSION_M = 0.0139
#: The study's law k1 = a + b·|p| (N/m, N/m per kPa), for comparison.
PUBLISHED_LAW = (75.41, 1.19)
SMOOTH_SAMPLES = 3


def press_forces_n(log: ForceLog, smooth_samples: int = SMOOTH_SAMPLES) -> FloatArray:
    """Force of each press (burst) of a log: smoothed peak above the resting baseline."""
    force = log.samples["force_n"].to_numpy(dtype=np.float64)
    width = max(int(smooth_samples), 1)
    smooth = np.convolve(force, np.ones(width) / width, mode="same") if force.size >= width else force
    starts = log.bursts["start_index"].to_numpy(dtype=np.int64)
    ends = log.bursts["end_index"].to_numpy(dtype=np.int64)
    peaks = [float(np.max(smooth[a:b])) - log.baseline_n for a, b in zip(starts, ends, strict=True) if b > a]
    return np.asarray(peaks, dtype=np.float64)


@dataclass(frozen=True)
class StaticStiffness:
    """Per-level stiffness and the fitted law k1 = a + b·|p|."""

    levels_kpa: FloatArray
    k1_npm: FloatArray
    n_presses: tuple[int, ...]
    k1_a_npm: float
    k1_b_npm_per_kpa: float
    ci_a: tuple[float, float]
    ci_b: tuple[float, float]
    compression_m: float
    k1_sd_npm: FloatArray | None = None  # spread of the presses of each level

    @property
    def residual_npm(self) -> FloatArray:
        """Per-level stiffness minus the straight line (how far the law is from the data)."""
        return np.asarray(self.k1_npm - (self.k1_a_npm + self.k1_b_npm_per_kpa * np.abs(self.levels_kpa)),
                          dtype=np.float64)

    def to_dict(self) -> dict[str, object]:
        """Plain values for JSON and the model file."""
        return {
            "levels_kpa": self.levels_kpa.tolist(), "k1_npm": self.k1_npm.tolist(),
            "k1_sd_npm": None if self.k1_sd_npm is None else self.k1_sd_npm.tolist(),
            "n_presses": list(self.n_presses), "residual_npm": self.residual_npm.tolist(),
            "k1_a_npm": self.k1_a_npm, "k1_b_npm_per_kpa": self.k1_b_npm_per_kpa,
            "ci_a": list(self.ci_a), "ci_b": list(self.ci_b), "compression_m": self.compression_m,
            "published": {"k1_a_npm": PUBLISHED_LAW[0], "k1_b_npm_per_kpa": PUBLISHED_LAW[1]},
        }


def static_stiffness(peaks_by_level: Mapping[float, Sequence[float]], *,
                     compression_m: float = STUDY_COMPRESSION_M) -> StaticStiffness:
    """Stiffness per vacuum level (mean press force / compression) and the linear law through them."""
    if not compression_m > 0:
        raise InputError(f"compression should be > 0 m, got {compression_m}", "--compression-m")
    usable = [p for p in sorted(peaks_by_level, key=abs) if len(peaks_by_level[p]) > 0]
    if len(usable) < 2:
        raise InputError(f"need presses at two or more vacuum levels, got {len(usable)}", "--force-log")
    p = np.abs(np.array(usable, dtype=np.float64))
    k = np.array([float(np.mean(peaks_by_level[v])) / compression_m for v in usable])
    sd = np.array([float(np.std(peaks_by_level[v])) / compression_m for v in usable])
    X = np.column_stack([np.ones_like(p), p])
    coef, *_ = np.linalg.lstsq(X, k, rcond=None)
    resid = k - X @ coef
    dof = max(p.size - 2, 1)
    cov = float(resid @ resid) / dof * np.linalg.inv(X.T @ X)
    sa, sb = math.sqrt(cov[0, 0]), math.sqrt(cov[1, 1])
    a, b = float(coef[0]), float(coef[1])
    return StaticStiffness(
        levels_kpa=-p, k1_npm=k, n_presses=tuple(len(peaks_by_level[v]) for v in usable),
        k1_a_npm=a, k1_b_npm_per_kpa=b, ci_a=(a - Z95 * sa, a + Z95 * sa),
        ci_b=(b - Z95 * sb, b + Z95 * sb), compression_m=compression_m, k1_sd_npm=sd,
    )


def force_log_levels(items: Sequence[str]) -> dict[float, Path]:
    """`P=FILE` items and folders of `{P}.txt` logs → {vacuum kPa (≤ 0): log file}."""
    out: dict[float, Path] = {}
    for item in items:
        folder = Path(item)
        if "=" not in item and folder.is_dir():
            for f in sorted(folder.glob("*.txt")):
                if re.fullmatch(r"\d+(\.\d+)?", f.stem):
                    out[-abs(float(f.stem))] = f
            continue
        level, sep, name = item.partition("=")
        if not sep:
            raise InputError(f"expected P=FILE or a folder of P.txt logs, got {item!r}", "--force-log")
        try:
            out[-abs(float(level))] = Path(name)
        except ValueError:
            raise InputError(f"vacuum level {level!r} is not a number", "--force-log") from None
    return out


def static_stiffness_from_logs(logs: Mapping[float, Path], *, compression_m: float = STUDY_COMPRESSION_M,
                               calibration: ForceCalibration | None = None) -> StaticStiffness:
    """Read each level's force log (`read_force_log`) and fit the stiffness law."""
    peaks = {level: press_forces_n(read_force_log(path, calibration)).tolist() for level, path in logs.items()}
    return static_stiffness(peaks, compression_m=compression_m)
