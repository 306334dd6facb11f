"""The study's 2-DoF mass-spring-damper model: its parameters and static deformation ratio.

Equations of motion in contact (downward positive, x0 arm, x1 fingertip, x2 key):

    m1 ẍ1 = k0 (x0 − x1) − k1 (x1 − x2) + c0 (ẋ0 − ẋ1) − c1 (ẋ1 − ẋ2)
    m2 ẍ2 = k1 (x1 − x2) − k2 x2 + c1 (ẋ1 − ẋ2) − c2 ẋ2

Parameters (the soft finger's stiffness grows with vacuum, k1 = 75.41 + 1.19·|p| N/m) live in
`MSDParams`; `MSDParams.at(vacuum_kpa)` resolves them to the numbers of one vacuum level
(`LinearParams`). This module holds the parameters only (and the static ratio they imply);
what is computed with them lives above it: the model as a linear system (state space, exact
simulation, frequency response) in `linear.py`, its inverse (key trajectory in, arm trajectory
out) in `inverse.py`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, overload

import numpy as np
import numpy.typing as npt

__all__ = [
    "LinearParams",
    "MSDParams",
    "deformation_ratio",
    "error_rate",
    "static_deformation_ratio",
]

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
    coupling) default to k1 and c1, as in the study's scripts; `k0_over_k1` and `c0_over_c1`
    scale them (the same finger on both sides), `k0_npm`/`c0_nspm` fix them outright.
    """

    m1_kg: float = 0.070
    m2_kg: float = 0.03405
    k1_a_npm: float = 75.41
    k1_b_npm_per_kpa: float = 1.19
    c1_nspm: float = 0.50
    k2_npm: float = 300.0  # 0.30 N/mm
    c2_nspm: float = 0.30
    k0_npm: float | None = None  # None: k0 = k0_over_k1 · k1 at the same vacuum
    c0_nspm: float | None = None  # None: c0 = c0_over_c1 · c1
    # The arm-fingertip coupling as a fixed ratio to the fingertip-key one (the same soft finger
    # stiffens with vacuum on both sides); 1 is the study's k0 = k1, c0 = c1.
    k0_over_k1: float = 1.0
    c0_over_c1: float = 1.0
    k1_table: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        for name in ("m1_kg", "m2_kg"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} should be > 0, got {getattr(self, name)}.")
        for name in ("c1_nspm", "k2_npm", "c2_nspm", "k0_npm", "c0_nspm", "k0_over_k1", "c0_over_c1"):
            value = getattr(self, name)
            if value is not None and not value >= 0.0:
                raise ValueError(f"{name} should be >= 0, got {value}.")
        for name in ("k0_over_k1", "c0_over_c1"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} should be > 0, got {getattr(self, name)}.")
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
            k0_npm=self.k0_over_k1 * k1 if self.k0_npm is None else self.k0_npm,
            c0_nspm=self.c0_over_c1 * self.c1_nspm if self.c0_nspm is None else self.c0_nspm,
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
