"""A piano and finger for the sim rig made by the independent truth lab (`tests/truth`).

`play` is then tested on physics that shares no code, functional form or number with
`pianobot.physics`: the truth lab's own moveL arm, RK4 finger–key integrator (unilateral pad,
its own base parameter sets) and two-contact piano with latency and jitter. `TruthWorld` gives
the simulated rig what it asks of a world (`keystroke`, `vacuum_settle_s` and the piano's
re-trigger depth); the planner sees none of it, only the MIDI the rig collects.
"""

from __future__ import annotations

import hashlib
import math
from types import SimpleNamespace
from typing import Any

import numpy as np

from pianobot.physics.trajectory import Press, press_timing
from tests.truth.arm import Move
from tests.truth.base import BASE_SETS
from tests.truth.catalogue import piano_for
from tests.truth.plant import Plant
from tests.truth.readout import read_key

SETTLE_S = 0.4  # simulated after the arm is back up: the key returns and rings out
RECORD_EVERY = 4  # ≈ 83 µs: fine enough for the piano's contacts
MOCAP_HZ = 120.0


class TruthWorld:
    """One of the truth lab's base sets at any vacuum, read by its piano (fixed at one vacuum)."""

    def __init__(self, base: str = "stiff-key", seed: int = 0, piano_vacuum_kpa: float = -60.0) -> None:
        self.base = BASE_SETS[base]
        self.seed = seed
        self.piano = piano_for(base, piano_vacuum_kpa)
        release = self.piano.release_m
        self.model = SimpleNamespace(readout_params=lambda: SimpleNamespace(release_m=release))

    def vacuum_settle_s(self, from_kpa: float, to_kpa: float) -> float:
        """A first-order regulator with a 1.2 s time constant, settled within 0.5 kPa."""
        step = abs(float(to_kpa) - float(from_kpa))
        return 0.0 if step <= 0.5 else 1.2 * math.log(step / 0.5)

    def keystroke(self, press: Press, vacuum_kpa: float, *, note: int = 60, t0_s: float = 0.0,
                  key: str = "", block: str | None = None) -> Any:
        """One keystroke from rest, as the sim rig's devices read it (absolute times)."""
        del block
        timing = press_timing(press)
        moves = _moves(press, timing)
        end_s = timing.t_end_s + SETTLE_S
        traj = Plant(self.base, float(vacuum_kpa), press.distance_m).simulate(moves, end_s, record_every=RECORD_EVERY)
        t, x0, x1, x2 = traj.t_s, traj["x0_m"], traj["x1_m"], traj["x2_m"]
        rng = np.random.default_rng(int.from_bytes(hashlib.sha256(f"{self.seed}|{key}".encode()).digest()[:8], "big"))
        midi = []
        for event in read_key(self.piano, t, x2):
            stamp = t0_s + event.t_s + self.piano.latency_s + rng.uniform(-1, 1) * self.piano.jitter_s
            midi.append(SimpleNamespace(t_s=round(stamp, 3), type=event.kind, note=note, velocity=event.velocity))
        frames = np.arange(0.0, t[-1], 1.0 / MOCAP_HZ)
        on = next((e for e in read_key(self.piano, t, x2) if e.kind == "note_on"), None)
        return SimpleNamespace(
            t0_s=t0_s, duration_s=float(t[-1]), truth_t_s=t0_s + t, truth_x0_m=x0, truth_x1_m=x1, truth_x2_m=x2,
            arm_t_s=t0_s + t, arm_x0_m=x0, mocap_t_s=t0_s + frames, mocap_x0_m=np.interp(frames, t, x0),
            mocap_x1_m=np.interp(frames, t, x1), mocap_x2_m=np.interp(frames, t, x2), midi=tuple(midi),
            key_speed_at_trigger_mps=math.nan if on is None else on.speed_mps, max_key_travel_m=float(np.max(x2)),
        )


def _moves(press: Press, timing: Any) -> list[Move]:
    """The press as the truth lab's rest-to-rest moveLs (down positive), from motion start 0."""
    travel = press.distance_m + press.depth_m
    moves = []
    if press.approach_m > 0:
        moves.append(Move(0.0, press.approach_m, press.travel_velocity_mps, press.travel_acceleration_mps2))
    moves.append(Move(timing.t_down_start_s, travel - press.approach_m, press.down_velocity_mps,
                      press.acceleration_mps2))
    moves.append(Move(timing.t_hold_end_s, -(travel - press.retract_m), press.up_velocity_mps, press.acceleration_mps2))
    if press.retract_m > 0:
        moves.append(Move(timing.t_lifted_s, -press.retract_m, press.travel_velocity_mps, press.travel_acceleration_mps2))
    return moves
