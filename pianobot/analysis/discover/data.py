"""What discovery compares: measured keystrokes and the model's prediction of each.

A `Keystroke` is one press as measured (mocap samples at their own times, MIDI outcome); a
`Prediction` is the model's account of the same press at the same sample times, with the model
states that localisation bins the residual by. Both are plain values so that localisation and
the decision can be tested on synthetic arrays without any simulator.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from pianobot.physics.trajectory import Press

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

SIGNALS = ("x0", "x1", "x2")
PHASES = ("approach", "press", "hold", "release", "return")


def _empty() -> FloatArray:
    return np.empty(0)


@dataclass(frozen=True)
class Keystroke:
    """One measured keystroke.

    `x_m` is (3, n): arm, fingertip and key at `t_s` (s after motion start), NaN where the
    marker was not seen. MIDI fields are NaN when the key stayed silent; `sounded` is None when no
    MIDI was recorded at all.
    """

    key_id: str
    press: Press
    vacuum_kpa: float
    t_s: FloatArray = field(default_factory=_empty)
    x_m: FloatArray = field(default_factory=lambda: np.empty((3, 0)))
    on_velocity: float = float("nan")
    t_on_s: float = float("nan")
    t_off_s: float = float("nan")
    sounded: bool | None = None

    @property
    def has_motion(self) -> bool:
        """True when any position sample was measured."""
        return bool(self.t_s.size and np.isfinite(self.x_m).any())

    @property
    def hold_s(self) -> float:
        """Measured time between note-on and note-off (NaN when either is missing)."""
        return self.t_off_s - self.t_on_s


@dataclass(frozen=True)
class Prediction:
    """The model's account of one keystroke at that keystroke's sample times."""

    x_m: FloatArray  # (3, n) arm, fingertip, key
    v2_mps: FloatArray  # key velocity
    compression_m: FloatArray  # finger compression (> 0 in contact)
    contact_force_n: FloatArray  # finger-on-key force the model needs (negative would pull)
    phase: IntArray  # index into PHASES
    on_velocity: float = float("nan")
    t_on_s: float = float("nan")
    t_off_s: float = float("nan")
    sounded: bool = False

    @property
    def hold_s(self) -> float:
        """Predicted time between note-on and note-off."""
        return self.t_off_s - self.t_on_s


def phase_labels(
    t_s: FloatArray, x0_m: FloatArray, compression_m: FloatArray, speed_floor_mps: float = 1e-4
) -> IntArray:
    """Label each sample approach | press | hold | release | return from the model's states.

    Arm motion decides the direction (the arm is the input, so its sign is never ambiguous);
    contact decides approach vs press and release vs return.
    """
    n = t_s.size
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    v0 = np.gradient(x0_m, t_s) if n > 1 else np.zeros(n)
    after_bottom = np.zeros(n, dtype=bool)
    bottom = int(np.argmax(x0_m))
    after_bottom[bottom:] = True
    in_contact = compression_m > 0.0
    labels = np.full(n, PHASES.index("hold"), dtype=np.int64)
    moving_down = (v0 > speed_floor_mps) & ~after_bottom
    moving_up = (v0 < -speed_floor_mps) & after_bottom
    labels[moving_down & ~in_contact] = PHASES.index("approach")
    labels[moving_down & in_contact] = PHASES.index("press")
    labels[moving_up & in_contact] = PHASES.index("release")
    labels[after_bottom & ~in_contact] = PHASES.index("return")
    labels[~after_bottom & ~in_contact & ~moving_down] = PHASES.index("approach")
    return labels


def stratified_split(
    keystrokes: Sequence[Keystroke], held_out_fraction: float = 0.33, seed: int = 0
) -> tuple[IntArray, IntArray]:
    """Split keystroke indices into train / held-out, stratified by vacuum and speed.

    Keystrokes are grouped by vacuum level, sorted by down speed inside each group, and every
    k-th one (random phase per group) is held out, so both halves span the whole speed range.
    """
    if not 0.0 < held_out_fraction < 1.0:
        raise ValueError(f"held_out_fraction must be in (0, 1), got {held_out_fraction}")
    rng = np.random.default_rng(seed)
    step = max(2, round(1.0 / held_out_fraction))
    held: list[int] = []
    vacua = np.array([round(k.vacuum_kpa, 1) for k in keystrokes])
    for level in np.unique(vacua):
        group = [int(i) for i in np.flatnonzero(vacua == level)]
        group.sort(key=lambda i: (keystrokes[i].press.down_velocity_mps, keystrokes[i].key_id))
        start = int(rng.integers(step))
        held.extend(group[start::step])
    held_set = set(held)
    if len(held_set) == len(keystrokes) or not held_set:
        raise ValueError(f"cannot split {len(keystrokes)} keystrokes into train and held-out")
    train = np.array([i for i in range(len(keystrokes)) if i not in held_set], dtype=np.int64)
    return train, np.array(sorted(held_set), dtype=np.int64)
