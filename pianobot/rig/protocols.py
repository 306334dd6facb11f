"""The devices a rig is made of, as small Protocols.

Every backend (the simulated world, the UR5 over ur_rtde, a vacuum regulator, a USB-MIDI piano)
implements these; the runner and `play` only ever see the protocols. Times are seconds on the
run clock (`Clock.now()`), positions metres, displacements downward positive.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from pianobot.physics.trajectory import Press

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class MidiEvent:
    """One MIDI message from the piano, on the run clock."""

    t_s: float
    type: str  # "note_on" | "note_off" (a note_on with velocity 0 is reported as note_off)
    note: int
    velocity: int


@dataclass(frozen=True)
class Trace:
    """A sampled time series of vertical displacements (NaN where a sample is missing)."""

    t_s: FloatArray
    x0_m: FloatArray | None = None  # arm (TCP)
    x1_m: FloatArray | None = None  # fingertip
    x2_m: FloatArray | None = None  # key surface
    source: str = "arm"  # "arm" | "mocap" | "sim-truth"


@dataclass(frozen=True)
class PressRecord:
    """What the arm reports after one press."""

    t_start_s: float  # run-clock time the first downward move was sent
    t_end_s: float  # run-clock time the arm was back at its start height
    arm: Trace | None = None  # TCP z trace at the controller rate, if recorded
    warnings: tuple[str, ...] = ()  # e.g. "speed scaling 0.8 < 1 stretches every move"


@dataclass(frozen=True)
class KeystrokeResult:
    """Everything one keystroke produced, ready for the store."""

    press: PressRecord
    midi: tuple[MidiEvent, ...]
    traces: tuple[Trace, ...] = ()  # arm, mocap, sim-truth, as recorded
    vacuum_kpa_measured: float | None = None
    extra: dict[str, Any] = field(default_factory=dict)


@runtime_checkable
class Clock(Protocol):
    """The run clock: virtual for the simulated rig, monotonic wall time for hardware."""

    def now(self) -> float: ...

    def sleep(self, seconds: float) -> None: ...


@runtime_checkable
class Arm(Protocol):
    """A robot arm that presses one key along the vertical axis."""

    def connect(self) -> None:
        """Open (or re-open after a drop) the connection. Raises ConnectionLost if unreachable."""
        ...

    def move_to_key(self, note: int, distance_m: float) -> None:
        """Move to hover `distance_m` above the key surface of `note`."""
        ...

    def press(self, press: Press, note: int) -> PressRecord:
        """Down by distance+depth, hold, back up. Raises ConnectionLost or SafetyStop."""
        ...

    def make_safe(self) -> None:
        """Stop any motion and retract to a safe height. Never raises."""
        ...

    def close(self) -> None: ...

    def describe(self) -> dict[str, Any]: ...


@runtime_checkable
class Vacuum(Protocol):
    """The regulator that stiffens the particle-jamming finger (kPa gauge, <= 0)."""

    def set_kpa(self, vacuum_kpa: float) -> float:
        """Command a level, wait until it settles, return the measured (or commanded) level."""
        ...

    def vent(self) -> None:
        """Return to atmospheric pressure. Never raises."""
        ...

    def describe(self) -> dict[str, Any]: ...


@runtime_checkable
class Keyboard(Protocol):
    """MIDI input from the piano; events are stamped on the run clock when they arrive."""

    def start(self) -> None: ...

    def events_between(self, t_from_s: float, t_to_s: float) -> list[MidiEvent]:
        """Events with t_from_s <= t_s < t_to_s (assignment by time window, never by count)."""
        ...

    def close(self) -> None: ...

    def describe(self) -> dict[str, Any]: ...


@runtime_checkable
class Mocap(Protocol):
    """A motion-capture stream (optional on a rig)."""

    def trace_between(self, t_from_s: float, t_to_s: float) -> Trace: ...

    def describe(self) -> dict[str, Any]: ...
