"""Base parameter sets of the truth lab: the linear finger–key chain without any hidden effect.

The chain is arm —(k0, c0)— finger mass m1 —(k1, c1, unilateral contact)— key mass m2
—(k2, c2)— frame, displacements downward from rest. The study published m1 = 70 g,
m2 = 34.05 g, k1 = 75.41 + 1.19·|p| N/m, c1 = 0.5, k2 = 300 N/m, c2 = 0.3, k0 = k1, c0 = c1.
None of the sets below uses those numbers: each changes the finger mass, unties k0 from k1 and
c0 from c1, and moves the key's stiffness and mass, while staying physically plausible (the
coupled key rings at 7–11 Hz over the vacuum levels a set is used at, a press of the study's depths
moves the key a few millimetres, the finger stiffens with vacuum).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class BaseParams:
    """One base set; the finger stiffnesses depend on vacuum (gauge kPa, ≤ 0).

    k1(p) = k1_0 + k1_per_kpa·|p|; the finger body is `k0_ratio` times stiffer than the pad,
    k0(p) = k0_ratio·k1(p) (the study tied k0 = k1).
    """

    name: str
    m1_kg: float
    m2_kg: float
    k1_0_npm: float
    k1_per_kpa_npm: float
    k0_ratio: float
    c0_nspm: float
    c1_nspm: float
    k2_npm: float
    c2_nspm: float
    take_acceleration_mps2: float  # moveL acceleration of the mocap takes made on this set
    note: str = ""

    def k1_npm(self, vacuum_kpa: float) -> float:
        """Pad (finger–key contact) stiffness at a vacuum level."""
        return self.k1_0_npm + self.k1_per_kpa_npm * abs(vacuum_kpa)

    def k0_npm(self, vacuum_kpa: float) -> float:
        """Finger body (arm–finger) stiffness at a vacuum level."""
        return self.k0_ratio * self.k1_npm(vacuum_kpa)

    def at(self, vacuum_kpa: float) -> dict[str, float]:
        """The chain's numbers at one vacuum level (SI, units in the keys)."""
        return {
            "m1_kg": self.m1_kg,
            "m2_kg": self.m2_kg,
            "k0_npm": self.k0_npm(vacuum_kpa),
            "c0_nspm": self.c0_nspm,
            "k1_npm": self.k1_npm(vacuum_kpa),
            "c1_nspm": self.c1_nspm,
            "k2_npm": self.k2_npm,
            "c2_nspm": self.c2_nspm,
        }

    def to_dict(self) -> dict[str, float | str]:
        return asdict(self)


BASE_SETS: dict[str, BaseParams] = {
    s.name: s
    for s in (
        BaseParams(
            "light-finger", m1_kg=0.050, m2_kg=0.031, k1_0_npm=52.0, k1_per_kpa_npm=0.92,
            k0_ratio=1.35, c0_nspm=0.85, c1_nspm=0.38, k2_npm=270.0, c2_nspm=0.24,
            take_acceleration_mps2=1.0,
            note="lighter finger, body stiffer than the pad (k0 = 1.35 k1), own c0",
        ),
        BaseParams(
            "stiff-key", m1_kg=0.060, m2_kg=0.038, k1_0_npm=84.0, k1_per_kpa_npm=1.05,
            k0_ratio=0.80, c0_nspm=0.42, c1_nspm=0.62, k2_npm=350.0, c2_nspm=0.36,
            take_acceleration_mps2=1.0,
            note="stiffer, heavier key; body softer than the pad (k0 = 0.8 k1)",
        ),
        BaseParams(
            "soft-key", m1_kg=0.055, m2_kg=0.041, k1_0_npm=72.0, k1_per_kpa_npm=1.22,
            k0_ratio=1.15, c0_nspm=0.60, c1_nspm=0.46, k2_npm=235.0, c2_nspm=0.27,
            take_acceleration_mps2=0.8,
            note="softer key spring with a heavier key, moveL at 0.8 m/s^2",
        ),
        BaseParams(
            "light-key", m1_kg=0.066, m2_kg=0.027, k1_0_npm=79.0, k1_per_kpa_npm=1.12,
            k0_ratio=1.30, c0_nspm=0.55, c1_nspm=0.52, k2_npm=310.0, c2_nspm=0.20,
            take_acceleration_mps2=1.2,
            note="light, lightly damped key; moveL at 1.2 m/s^2",
        ),
    )
}  # fmt: skip

# The study's published numbers: never used to generate data, only to prove that no set equals them.
PUBLISHED = {
    "m1_kg": 0.070, "m2_kg": 0.03405, "k1_0_npm": 75.41, "k1_per_kpa_npm": 1.19,
    "k0_ratio": 1.0, "c1_nspm": 0.50, "k2_npm": 300.0, "c2_nspm": 0.30,
}  # fmt: skip
