"""The one keystroke container of the grey-box fitter: what was commanded, measured and heard.

Identification and discovery read the same `KeystrokeBatch`; it holds, per keystroke,

- the vacuum level and the fingertip-key gap at the start (`distance_m`);
- the **commanded press** (down/up speed, acceleration, depth, hold; NaN where the data do not
  record it, e.g. a Motive take or a log without the acceleration): the commanded drive of the
  forward model uses it, and fits what is missing rather than assuming it;
- the **measured trajectories** (optional): fingertip x1 and key x2 on one uniform frame grid,
  each row on its own clock phase, and the arm trace x0 that drives the model on its own grid
  (see `trajectories.py` for how the store's samples become these arrays);
- the **MIDI outcome** (optional): on-velocity, note-on time after motion start, hold, and
  whether the key sounded.

A MIDI-only batch (an old keystroke log) has no trajectories: its frame grid is empty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace

import numpy as np
import numpy.typing as npt

from pianobot.analysis.greybox.noise import noise_sigma_m
from pianobot.physics.trajectory import Press
from pianobot.plan.trial import press_from
from pianobot.spec.parameters import PRESS_PARAMETERS, recorded_or_followed

FloatArray = npt.NDArray[np.float64]

#: Columns of the commanded press (the parameter table's press parameters but the distance, a
#: row field of its own; NaN where not recorded).
COMMAND_FIELDS: tuple[str, ...] = tuple(n for n in PRESS_PARAMETERS if n != "distance_m")
#: Per-keystroke facts of a batch besides its trajectories: NaN where not recorded.
_FACT_FIELDS = (*COMMAND_FIELDS, "command_start_s", "motion_start_s", "on_velocity", "t_on_s", "hold_midi_s",
                "sounded")
#: Per-keystroke arrays (n,) of a batch; `subset` indexes these and the (n, ...) trajectories.
_ROW_FIELDS = ("vacuum_kpa", "x0_m", "x1_m", "x2_m", "distance_m", "distance_read_m", "key_start_m", "t_offset_s",
               "input_x0_m", *_FACT_FIELDS)


def _empty() -> FloatArray:
    return np.zeros(0)


@dataclass(frozen=True, eq=False)
class KeystrokeBatch:
    """n keystrokes: outputs on a uniform grid t_s (T,) shifted per row, input on its own grid.

    Arrays x0/x1/x2 have shape (n, T) and are relative to rest; row i is sampled at
    `t_s + t_offset_s[i]` (`row_times_s`). T is 0 when nothing was tracked (MIDI only). The
    optional fields default to: no offsets, the finger starting on the key (`distance_m` 0), the
    input given by `x0_m` on `t_s`, no commanded press recorded and no MIDI.
    """

    trial_id: tuple[str, ...]
    vacuum_kpa: FloatArray  # (n,)
    t_s: FloatArray  # (T,)
    x0_m: FloatArray  # input at the output times, finite everywhere
    x1_m: FloatArray  # NaN where not measured
    x2_m: FloatArray
    distance_m: FloatArray = field(default_factory=_empty)  # (n,) fingertip-key gap at the start
    t_offset_s: FloatArray = field(default_factory=_empty)  # (n,) in [0, dt)
    input_t_s: FloatArray = field(default_factory=_empty)  # (T_in,) uniform
    input_x0_m: FloatArray = field(default_factory=_empty)  # (n, T_in) finite
    input_noise_m: float = math.nan  # white noise σ of the arm trace as sampled (NaN: from input_x0_m)
    clock_offset_s: float = 0.0  # output clock minus input clock (the input is already shifted)
    clock_offset_se_s: float = 0.0  # its standard error
    arm_source: str = ""  # where x0 comes from: "arm" (log), "mocap" (marker), "sim-truth", "" none
    # (n,) where the key starts below its rest position: 0 for a key at rest; a key that dry
    # friction held part-way down after the previous keystroke starts there (x2_m stays measured
    # from the key's own level before the keystroke, so it starts at 0 either way).
    key_start_m: FloatArray = field(default_factory=_empty)
    # The commanded press (NaN: not recorded).
    down_velocity_mps: FloatArray = field(default_factory=_empty)
    up_velocity_mps: FloatArray = field(default_factory=_empty)
    acceleration_mps2: FloatArray = field(default_factory=_empty)
    depth_m: FloatArray = field(default_factory=_empty)
    hold_s: FloatArray = field(default_factory=_empty)
    # When the press was commanded to start, on the keystroke's clock (t = 0 is where its motion
    # was seen to start): 0 for a run's own arm log, NaN when no one logged the command.
    command_start_s: FloatArray = field(default_factory=_empty)
    # Where the keystroke's motion was seen to start on its run's own clock (NaN: not known); a
    # clock that runs at another rate than the command's shows as a lag growing along the run.
    motion_start_s: FloatArray = field(default_factory=_empty)
    # The MIDI outcome (NaN: silent or not recorded; `sounded` NaN: no MIDI recorded).
    on_velocity: FloatArray = field(default_factory=_empty)
    t_on_s: FloatArray = field(default_factory=_empty)  # note-on after motion start
    hold_midi_s: FloatArray = field(default_factory=_empty)  # note-off minus note-on
    sounded: FloatArray = field(default_factory=_empty)  # 1 sounded, 0 silent, NaN unknown
    # (n,) where the distance was not recorded, the hover the loader read from the take (the
    # fingertip's travel until the key moved; `greybox.hover` corrects it); NaN where recorded.
    distance_read_m: FloatArray = field(default_factory=_empty)

    def __post_init__(self) -> None:
        n = len(self.trial_id)
        for name in ("distance_m", "key_start_m", "t_offset_s"):
            if getattr(self, name).size == 0:
                object.__setattr__(self, name, np.zeros(n))
        if self.distance_read_m.size == 0:
            object.__setattr__(self, "distance_read_m", np.full(n, np.nan))
        for name in _FACT_FIELDS:
            if getattr(self, name).size == 0:
                object.__setattr__(self, name, np.full(n, np.nan))
        for name in ("x0_m", "x1_m", "x2_m"):
            if getattr(self, name).size == 0:
                object.__setattr__(self, name, np.zeros((n, self.t_s.size)))
        if self.input_t_s.size == 0:
            object.__setattr__(self, "input_t_s", self.t_s)
            object.__setattr__(self, "input_x0_m", self.x0_m)
        if math.isnan(self.input_noise_m):
            object.__setattr__(self, "input_noise_m", noise_sigma_m(self.input_x0_m) if self.input_x0_m.size else 0.0)
        for name in _ROW_FIELDS:
            if getattr(self, name).shape[:1] != (n,):
                raise ValueError(f"{name} should have {n} rows, got shape {getattr(self, name).shape}.")
        if self.input_x0_m.shape != (n, self.input_t_s.size):
            raise ValueError(f"input_x0_m should have shape {(n, self.input_t_s.size)}, got {self.input_x0_m.shape}.")
        # An unrecorded (or impossible) up velocity is the down velocity: the parameter table's rule.
        object.__setattr__(self, "up_velocity_mps", recorded_or_followed(
            "up_velocity_mps", {"up_velocity_mps": self.up_velocity_mps, "down_velocity_mps": self.down_velocity_mps}))

    @property
    def n(self) -> int:
        return len(self.trial_id)

    @property
    def dt_s(self) -> float:
        """Output sample interval (0 without trajectories)."""
        return float(self.t_s[1] - self.t_s[0]) if self.t_s.size > 1 else 0.0

    @property
    def run_ids(self) -> npt.NDArray[np.str_]:
        """(n,) the run each keystroke came from: its trial id's prefix before "/" (the store
        loader's "run/trial"; the whole id when it has none)."""
        return np.array([tid.split("/", 1)[0] for tid in self.trial_id])

    @property
    def start_gap_m(self) -> FloatArray:
        """(n,) the fingertip-key gap at the start: the distance, plus how far below its rest
        position a key held down by friction starts."""
        return np.asarray(self.distance_m + self.key_start_m, dtype=np.float64)

    @property
    def has_motion(self) -> bool:
        """True when the key was tracked (fingertip and key trajectories to fit)."""
        return self.t_s.size > 1 and bool(np.isfinite(self.x2_m).any())

    @property
    def has_midi(self) -> bool:
        """True when the piano's MIDI was recorded (sounded or silent known for some keystroke)."""
        return bool(np.isfinite(self.sounded).any())

    @property
    def arm_measured(self) -> bool:
        """True when a measured arm trace drives the model (not the commanded press)."""
        return self.has_motion and self.arm_source in ("arm", "mocap")

    @property
    def levels_kpa(self) -> tuple[float, ...]:
        """The vacuum levels, as |p| ascending."""
        return tuple(sorted(set(np.abs(self.vacuum_kpa).tolist())))

    def row_times_s(self, i: int) -> FloatArray:
        """Sample times of keystroke i (its frames' own clock phase)."""
        return np.asarray(self.t_s + self.t_offset_s[i], dtype=np.float64)

    def press(self, i: int, acceleration_mps2: float | None = None) -> Press:
        """The commanded press of keystroke i; `acceleration_mps2` stands in for one not recorded.

        Raises:
            ValueError: when the speed or depth was not recorded, or the acceleration is
                neither recorded nor given.
        """
        accel = self.acceleration_mps2[i]
        if not math.isfinite(accel):
            if acceleration_mps2 is None:
                raise ValueError(f"keystroke {self.trial_id[i]} records no acceleration and none was given.")
            accel = acceleration_mps2
        down, depth = float(self.down_velocity_mps[i]), float(self.depth_m[i])
        if not (math.isfinite(down) and down > 0 and math.isfinite(depth) and depth > 0):
            raise ValueError(f"keystroke {self.trial_id[i]} records no commanded speed and depth.")
        # By name; an unrecorded hold takes the table's default (the up velocity already follows).
        return press_from({"distance_m": float(self.distance_m[i]), "depth_m": depth, "down_velocity_mps": down,
                           "up_velocity_mps": float(self.up_velocity_mps[i]), "acceleration_mps2": float(accel),
                           "hold_s": float(self.hold_s[i])})

    @property
    def commanded(self) -> bool:
        """True when every keystroke records its commanded speed and depth."""
        return bool(np.all(np.isfinite(self.down_velocity_mps) & np.isfinite(self.depth_m)))

    def subset(self, index: npt.ArrayLike) -> KeystrokeBatch:
        """Keystrokes `index` (an int array; repeats allowed, for the bootstrap)."""
        idx = np.asarray(index, dtype=np.intp)
        rows = {name: getattr(self, name)[idx] for name in _ROW_FIELDS}
        return replace(self, trial_id=tuple(self.trial_id[i] for i in idx), **rows)

    def without_trajectories(self) -> KeystrokeBatch:
        """The same keystrokes with only what was commanded and heard (no frames)."""
        n = self.n
        keep = {f.name: getattr(self, f.name) for f in fields(self)
                if f.name in ("trial_id", "vacuum_kpa", "distance_m", "key_start_m", *_FACT_FIELDS)}
        return KeystrokeBatch(t_s=np.zeros(0), x0_m=np.zeros((n, 0)), x1_m=np.zeros((n, 0)),
                              x2_m=np.zeros((n, 0)), **keep)
