"""Mapping a song's loudness onto what the finger can play.

A soft finger inside its safety envelope reaches only part of the MIDI velocity scale (the
study's mostly produced 1–25). `mapped` stretches the song's velocity range linearly onto the
reachable range, keeping the contrasts (a song at one loudness keeps its place on the MIDI
scale: 127 the loudest reachable, 1 the quietest); `absolute` keeps the written velocities and clips them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
DynamicsMode = Literal["mapped", "absolute"]
DYNAMICS_MODES: tuple[str, ...] = ("mapped", "absolute")
MIDI_MAX = 127.0  # the loudest MIDI velocity


@dataclass(frozen=True)
class DynamicsMap:
    """Song velocity → target on-velocity: linear onto the reachable range, or clipped."""

    mode: DynamicsMode
    song_range: tuple[float, float]
    target_range: tuple[float, float]

    @classmethod
    def fit(cls, song_velocities: npt.ArrayLike, reachable: tuple[float, float], mode: DynamicsMode) -> DynamicsMap:
        """The map for a song's velocities and the reachable (quietest, loudest) on-velocity."""
        v = np.asarray(song_velocities, dtype=np.float64)
        song = (float(v.min()), float(v.max())) if v.size else (0.0, 0.0)
        return cls(mode, song, (float(reachable[0]), float(reachable[1])))

    def apply(self, song_velocities: npt.ArrayLike) -> FloatArray:
        """Target on-velocities (floats: the model aims between MIDI steps too)."""
        v = np.asarray(song_velocities, dtype=np.float64)
        lo, hi = self.target_range
        if self.mode == "absolute":
            return np.asarray(np.clip(v, lo, hi), dtype=np.float64)
        s_lo, s_hi = self.song_range
        if s_hi - s_lo < 1e-9:
            # One loudness throughout (a score exported without dynamics, or marked ff or pp all
            # through): its place on the MIDI scale, so 127 is the loudest the finger can play,
            # 1 the quietest and 64 the middle, where it used to be the middle whatever it said.
            return np.full(v.shape, lo + self.one_loudness_fraction * (hi - lo))
        return np.asarray(lo + (v - s_lo) / (s_hi - s_lo) * (hi - lo), dtype=np.float64)

    @property
    def one_loudness_fraction(self) -> float:
        """Where a song at one loudness sits in the reachable range: its place on 1–127."""
        return float(np.clip((self.song_range[0] - 1.0) / (MIDI_MAX - 1.0), 0.0, 1.0))

    def describe(self) -> str:
        """The mapping as one line, e.g. `linear 25–115 → 1.8–9.4`."""
        lo, hi = self.target_range
        if self.mode == "absolute":
            return f"absolute, clipped to {lo:.1f}–{hi:.1f}"
        if self.song_range[1] - self.song_range[0] < 1e-9:
            at = lo + self.one_loudness_fraction * (hi - lo)
            return f"one loudness {self.song_range[0]:g} of 127 → {at:.1f} in {lo:.1f}–{hi:.1f}"
        return f"linear {self.song_range[0]:g}–{self.song_range[1]:g} → {lo:.1f}–{hi:.1f}"

    def to_dict(self) -> dict[str, Any]:
        return {
            "mode": self.mode,
            "song_range": list(self.song_range),
            "target_range": list(self.target_range),
            "text": self.describe(),
        }
