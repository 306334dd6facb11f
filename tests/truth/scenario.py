"""A truth scenario: one lab session (a mocap take or a MIDI-only log) with at most one hidden effect.

`Scenario` is pure data; `materialise(scenario, folder)` simulates it and writes what the lab
would have recorded plus `truth.json` (the answer). The same scenario and seed always give the
same bytes.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .arm import ArmServo, PressCommand
from .forms import Effect
from .motive import MocapObservation
from .plant import MOCAP_RATE_HZ, STEP_S
from .readout import Piano, VelocityCurve

KINDS = ("mocap", "midi")
STRENGTHS = ("strong", "weak", "clean")


@dataclass(frozen=True)
class TakeSchedule:
    """A zzz-style take: speeds × repeats of short moveL presses, the finger resting on the key.

    Each press goes down by distance + depth. `key_target_m` (instead of `depth_m`) asks for the
    depth that would push the key of the linear chain this far statically: a lab presses "to the
    bottom" by trying depths, the generator solves the chain's statics for it.
    """

    speeds_mps: tuple[float, ...] = tuple(float(v) for v in np.linspace(0.01, 0.08, 8))
    repeats: int = 3
    depth_m: float = 0.008
    key_target_m: float | None = None
    distance_m: float = 0.0  # > 0: the finger hovers above the key between presses
    acceleration_mps2: float | None = None  # None: the base set's take acceleration
    hold_s: float = 0.5
    gap_s: float = 1.2  # pause after each press (arm back at rest)
    group_gap_s: float = 3.0  # extra pause between speed groups
    lead_s: float = 2.0  # rest before the first press
    tail_s: float = 2.0  # rest after the last press
    jitter_s: float = 0.08  # the operator's script pauses vary a little

    def presses(
        self, acceleration_mps2: float, depth_m: float, rng: np.random.Generator
    ) -> list[PressCommand]:
        out = []
        t = self.lead_s
        for speed in self.speeds_mps:
            for _ in range(self.repeats):
                press = PressCommand(t, speed, acceleration_mps2, depth_m, self.distance_m,
                                     self.hold_s, speed)  # fmt: skip
                out.append(press)
                t = press.t_end_s + self.gap_s + float(rng.uniform(-1, 1)) * self.jitter_s
            t += self.group_gap_s
        return out


@dataclass(frozen=True)
class GridSchedule:
    """The study's soft-finger sweep: acc × vel × depth at one vacuum, hovering 5 cm above."""

    accelerations_mps2: tuple[float, ...] = (0.1, 0.5, 1.0)
    speeds_mps: tuple[float, ...] = tuple(float(v) for v in np.linspace(0.01, 0.08, 15))
    depths_m: tuple[float, ...] = (0.02, 0.03, 0.04)
    distance_m: float = 0.05
    hold_s: float = 0.0
    angle_deg: float = 45.0
    first_start_s: float = 5.0  # motion start of the first keystroke on the MIDI clock
    pause_s: float = 1.0  # between the arm's return and the next keystroke
    pause_sd_s: float = 0.03

    def presses(self) -> list[PressCommand]:
        return [
            PressCommand(0.0, v, a, d, self.distance_m, self.hold_s, v)
            for a in self.accelerations_mps2
            for v in self.speeds_mps
            for d in self.depths_m
        ]


@dataclass(frozen=True)
class Scenario:
    """One session of the truth lab (see the package README for the suite)."""

    name: str
    kind: str  # "mocap" | "midi"
    base: str  # a key of base.BASE_SETS
    vacuum_kpa: float
    seed: int
    strength: str = "clean"  # "strong" | "weak" | "clean"
    effect: Effect | None = None
    take: TakeSchedule = field(default_factory=TakeSchedule)
    grid: GridSchedule = field(default_factory=GridSchedule)
    piano: Piano = field(default_factory=Piano)
    observation: MocapObservation = field(default_factory=MocapObservation)
    description: str = ""
    frame_rate_hz: float = MOCAP_RATE_HZ  # the capture's frame rate (a divisor of the plant's step rate)

    def __post_init__(self) -> None:
        if abs(1.0 / (self.frame_rate_hz * STEP_S) - round(1.0 / (self.frame_rate_hz * STEP_S))) > 1e-9:
            raise ValueError(f"{self.name}: frame rate {self.frame_rate_hz} Hz does not divide the plant's "
                             f"{1.0 / STEP_S:g} steps/s")
        if self.kind not in KINDS:
            raise ValueError(f"scenario kind should be one of {KINDS}, got {self.kind!r}")
        if self.strength not in STRENGTHS:
            raise ValueError(f"strength should be one of {STRENGTHS}, got {self.strength!r}")
        if (self.effect is None) != (self.strength == "clean"):
            raise ValueError(f"{self.name}: a clean scenario has no effect, others have one")
        if self.effect is not None:
            where = self.effect.info.where
            if where == "piano" and self.kind != "midi":
                raise ValueError(f"{self.name}: a piano effect needs a MIDI-only scenario")
            if where in ("arm", "mocap") and self.kind != "mocap":
                raise ValueError(f"{self.name}: a {where} effect needs a mocap take")

    def servo(self) -> ArmServo:
        """How the arm follows its command (exact unless the hidden effect is an arm one)."""
        e = self.effect
        if e is None or e.info.where != "arm":
            return ArmServo()
        if e.form == "servo":
            return ArmServo("servo", freq_hz=e.params["freq_hz"], zeta=e.params["zeta"])
        return ArmServo("lag" if e.form == "first_order" else "delay", tau_s=e.params["tau_s"])

    def mocap_clock(self) -> tuple[float, float]:
        """(offset s, rate error ppm) of the mocap clock against the arm's: zero unless hidden."""
        e = self.effect
        if e is None or e.info.where != "mocap":
            return 0.0, 0.0
        return e.params["delay_s"], e.params.get("rate_ppm", 0.0)

    def plant_effects(self) -> tuple[Effect, ...]:
        return () if self.effect is None or self.effect.info.where != "plant" else (self.effect,)

    def piano_used(self) -> Piano:
        """The piano with the hidden velocity curve, if that is the effect."""
        e = self.effect
        if e is None or e.info.where != "piano":
            return self.piano
        if e.form == "tanh":
            curve = VelocityCurve("tanh", exponent=e.params["exponent"],
                                  saturation=e.params["saturation"])  # fmt: skip
        else:
            curve = VelocityCurve("rational", knee=e.params["knee"])
        return replace(self.piano, curve=curve, full_scale_mps=e.params["full_scale_mps"])

    def without_effect(self) -> Scenario:
        """The same session with the hidden effect switched off (for the effect's size)."""
        return replace(self, effect=None, strength="clean", name=self.name + "-off")
