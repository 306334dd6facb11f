"""The keystroke sequence, the same for every backend: vacuum, position, press, collect.

One keystroke: set the vacuum if it changed (the regulator settles, seconds), hover over the key
if the note or the run-up distance changed, press, wait `settle_s` so the key returns and the
last MIDI message arrives (the study's scripts slept 0.5 s around every press), then collect the
MIDI events and the mocap trace by time window from motion start to the end of the wait. MIDI is
assigned to a keystroke by time, never by counting messages, so a lost or extra message cannot
shift every later keystroke.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from pianobot.physics.trajectory import Press
from pianobot.rig.protocols import Arm, Clock, Keyboard, KeystrokeResult, Mocap, Trace, Vacuum


class TrialLike(Protocol):
    """What the station needs of a planned trial (`pianobot.plan.Trial` satisfies it)."""

    @property
    def trial_id(self) -> str: ...

    @property
    def index(self) -> int: ...

    @property
    def note(self) -> int: ...

    @property
    def vacuum_kpa(self) -> float: ...

    @property
    def distance_m(self) -> float: ...

    def press(self) -> Press: ...


# Called with (trial, attempt) right before the press is sent; the sim rig uses it to give the
# world the keystroke's identity and to fire injected faults.
BeforePress = Callable[[TrialLike, int], None]


@dataclass(frozen=True)
class StationSettings:
    """How a keystroke is collected."""

    settle_s: float = 0.5  # wait after the arm is back, before the MIDI window closes
    after_vacuum_change_s: float = 5.0  # from the command: regulator and jammed particles settle
    record_arm: bool = True
    record_mocap: bool = True


class Station:
    """Runs one keystroke on a set of devices; remembers vacuum level and hover position."""

    def __init__(
        self,
        arm: Arm,
        vacuum: Vacuum,
        keyboard: Keyboard,
        mocap: Mocap | None,
        clock: Clock,
        settings: StationSettings,
        before_press: BeforePress | None = None,
    ) -> None:
        self.arm = arm
        self.vacuum = vacuum
        self.keyboard = keyboard
        self.mocap = mocap
        self.clock = clock
        self.settings = settings
        self.before_press = before_press
        self._vacuum_kpa: float | None = None
        self._vacuum_measured_kpa: float | None = None
        self._hover: tuple[int, float] | None = None

    def forget_position(self) -> None:
        """After a reconnect or a stop the arm may be anywhere: hover again before the next press."""
        self._hover = None

    def forget_vacuum(self) -> None:
        """After venting, the next keystroke sets the level again."""
        self._vacuum_kpa = None
        self._vacuum_measured_kpa = None

    def keystroke(self, trial: TrialLike, attempt: int = 1) -> KeystrokeResult:
        """Execute one planned keystroke and gather what it produced.

        Raises whatever the devices raise (ConnectionLost, SafetyStop, SafetyViolation); the
        runner decides what to do about it.
        """
        if self._vacuum_kpa is None or not math.isclose(self._vacuum_kpa, trial.vacuum_kpa):
            t_command_s = self.clock.now()
            self._vacuum_kpa = None  # unknown until the regulator reports back
            self._vacuum_measured_kpa = self.vacuum.set_kpa(trial.vacuum_kpa)
            # set_kpa may already have waited for the regulator; the particles need the rest.
            waited_s = self.clock.now() - t_command_s
            self.clock.sleep(self.settings.after_vacuum_change_s - waited_s)
            self._vacuum_kpa = trial.vacuum_kpa
        hover = (trial.note, trial.distance_m)
        if self._hover != hover:
            # Forget first: if the move fails half-way the arm is somewhere in between.
            self._hover = None
            self.arm.move_to_key(trial.note, trial.distance_m)
            self._hover = hover
        if self.before_press is not None:
            self.before_press(trial, attempt)
        try:
            record = self.arm.press(trial.press(), trial.note)
        except BaseException:
            self._hover = None
            raise
        self.clock.sleep(self.settings.settle_s)
        t_to_s = max(self.clock.now(), record.t_end_s)
        midi = self.keyboard.events_between(record.t_start_s, t_to_s)
        traces: list[Trace] = []
        if self.settings.record_arm and record.arm is not None:
            traces.append(record.arm)
        if self.settings.record_mocap and self.mocap is not None:
            traces.append(self.mocap.trace_between(record.t_start_s, t_to_s))
        return KeystrokeResult(
            press=record,
            midi=tuple(midi),
            traces=tuple(traces),
            vacuum_kpa_measured=self._vacuum_measured_kpa,
        )


class Rig:
    """Devices, clock and keystroke sequence of one rig, as `open_rig` yields it.

    `keystroke(trial, attempt)` runs one planned keystroke; `reconnect()` re-opens the arm's
    link after a ConnectionLost; `clear_stop()` is called when an operator resumes a run that a
    protective stop ended; `make_safe()` retracts the arm and vents the vacuum.
    """

    def __init__(
        self,
        *,
        kind: str,
        arm: Arm,
        vacuum: Vacuum,
        keyboard: Keyboard,
        mocap: Mocap | None,
        clock: Clock,
        station: Station,
        finish: Callable[[KeystrokeResult], KeystrokeResult] | None = None,
        clear_stop: Callable[[], None] | None = None,
        description: dict[str, Any] | None = None,
    ) -> None:
        self.kind = kind
        self.arm = arm
        self.vacuum = vacuum
        self.keyboard = keyboard
        self.mocap = mocap
        self.clock = clock
        self.station = station
        self._finish = finish
        self._clear_stop = clear_stop
        self._description = dict(description or {})

    @property
    def simulated(self) -> bool:
        return self.kind == "sim"

    def keystroke(self, trial: TrialLike, attempt: int = 1) -> KeystrokeResult:
        """Run one keystroke (attempt numbers start at 1) and return what it produced."""
        result = self.station.keystroke(trial, attempt)
        return self._finish(result) if self._finish is not None else result

    def reconnect(self) -> None:
        """Re-open the arm's link (raises ConnectionLost if it is still down)."""
        self.station.forget_position()
        self.arm.connect()

    def clear_stop(self) -> None:
        """The operator has cleared a protective stop; the next keystroke hovers again first."""
        self.station.forget_position()
        if self._clear_stop is not None:
            self._clear_stop()

    def make_safe(self) -> None:
        """Stop and retract the arm, vent the vacuum; never raises."""
        for action in (self.arm.make_safe, self.vacuum.vent):
            try:
                action()
            except Exception:  # making safe must try every device
                pass
        self.station.forget_position()
        self.station.forget_vacuum()

    def close(self) -> None:
        """Make safe, then release the devices; never raises."""
        self.make_safe()
        for action in (self.keyboard.close, self.arm.close):
            try:
                action()
            except Exception:  # closing must try every device
                pass

    def describe(self) -> dict[str, Any]:
        """What run.json records about the rig: kind, devices, clock, settings."""
        devices: dict[str, Any] = {
            "arm": self.arm.describe(),
            "vacuum": self.vacuum.describe(),
            "keyboard": self.keyboard.describe(),
            "mocap": None if self.mocap is None else self.mocap.describe(),
        }
        describe_clock = getattr(self.clock, "describe", None)
        clock = describe_clock() if callable(describe_clock) else {"kind": type(self.clock).__name__}
        return {"kind": self.kind, **self._description, "devices": devices, "clock": clock}
