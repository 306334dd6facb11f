"""One configured truth lab (base numbers at a vacuum + hidden effects + arm servo) and its runs.

`Plant.simulate(moves, t_end_s)` integrates the chain from rest under a list of arm moves and
returns the recorded trajectories (`Trajectory`, SI units). The step is fixed (`STEP_S`, 1/400
of a 120 Hz mocap frame) so mocap frames land exactly on steps; the recording interval is a
whole number of steps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from . import kernel as K
from .arm import ArmServo, Move, breakpoints, move_table
from .base import BaseParams
from .forms import Effect, encode
from .kernel import integrate

FloatArray = npt.NDArray[np.float64]
MOCAP_RATE_HZ = 120.0
STEP_S = 1.0 / (MOCAP_RATE_HZ * 400)  # ≈ 20.8 µs
COARSE_STEPS = 20  # a long step (≈ 0.42 ms) while the key rests; divides 400


@dataclass(frozen=True)
class Trajectory:
    """Recorded channels (each an array over time), named as in `kernel.OUT_NAMES`."""

    data: FloatArray  # [n, N_OUT]
    events: int  # mode switches the integrator located
    unresolved: int  # steps where switching did not settle (should be 0)
    long_steps: int = 0  # steps taken as one long step while the key rested

    def __getitem__(self, name: str) -> FloatArray:
        return self.data[:, K.OUT_NAMES.index(name)]

    @property
    def t_s(self) -> FloatArray:
        return self.data[:, K.OUT_T]


@dataclass(frozen=True)
class Plant:
    """Base numbers at one vacuum, the finger's hover distance, hidden plant effects, arm servo."""

    base: BaseParams
    vacuum_kpa: float
    distance_m: float = 0.0
    effects: tuple[Effect, ...] = ()
    servo: ArmServo = field(default_factory=ArmServo)

    def params(self) -> FloatArray:
        """The kernel's parameter vector."""
        p = np.zeros(K.N_PARAMS)
        b = self.base.at(self.vacuum_kpa)
        p[K.M1], p[K.M2] = b["m1_kg"], b["m2_kg"]
        p[K.K0], p[K.C0] = b["k0_npm"], b["c0_nspm"]
        p[K.K1], p[K.C1] = b["k1_npm"], b["c1_nspm"]
        p[K.K2], p[K.C2] = b["k2_npm"], b["c2_nspm"]
        p[K.DIST] = self.distance_m
        p[K.ARM_KIND] = self.servo.code()
        p[K.ARM_TAU] = self.servo.tau_s
        p[K.ARM_WN] = 2.0 * math.pi * self.servo.freq_hz
        p[K.ARM_ZETA] = self.servo.zeta
        p[K.FR_VS] = 1.0
        p[K.BED_X] = math.inf
        for effect in self.effects:
            if effect.info.where == "plant":
                encode(effect, p)
        return p

    def simulate(
        self,
        moves: list[Move],
        t_end_s: float,
        record_every: int = 400,
        t_start_s: float = 0.0,
        coarse: int = COARSE_STEPS,
    ) -> Trajectory:
        """Integrate from rest at `t_start_s` to `t_end_s`; record every `record_every` steps.

        `coarse` steps are taken as one while the key rests (see `kernel.integrate`); 1 turns
        that off (the tests compare both).
        """
        table = move_table(moves)
        shift = self.servo.tau_s if self.servo.kind == "delay" else 0.0
        breaks = np.unique(np.concatenate([breakpoints(table), breakpoints(table, shift)]))
        n_steps = int(math.ceil((t_end_s - t_start_s) / STEP_S / record_every)) * record_every
        y0 = np.zeros(K.N_STATE)
        rec, _, counters = integrate(
            y0, self.params(), table, breaks, t_start_s, STEP_S, n_steps, record_every, coarse
        )
        return Trajectory(rec, int(counters[0]), int(counters[1]), int(counters[2]))
