"""The keystroke sequence, the same for every backend: vacuum, position, press, collect.

Two ways to press:

- `keystroke(trial)` — the sweep's sequence: set the vacuum if it changed (the regulator
  settles, seconds), hover over the key if the note or the run-up distance changed, press, wait
  `settle_s` so the key returns and the last MIDI message arrives (the study's scripts slept
  0.5 s around every press), then collect MIDI and mocap by time window.
- `press(trial, start_at_s=...)` — the player's timed press: the caller has already set the
  vacuum (`set_vacuum`) and hovered over the key (`move_to_key`, which returns how long the move
  took), so the press starts at a planned time on the rig clock (the virtual clock advances to
  it, a wall clock sleeps until it) and returns as soon as the arm is back up, without a settle
  pause unless one is asked for. The key still returns and rings on its own meanwhile; a
  backend that cannot press a key before it is back above its re-trigger depth waits for it
  and says so in the press record's warnings.

MIDI is assigned to a keystroke by time window (motion start → end of the arm's move or of the
settle pause), never by counting messages, so a lost or extra message cannot shift every later
keystroke. Events after the window (a late note-off) belong to whoever reads the next window.

A two-segment press (`Press.approach_m`/`retract_m`) is checked before it is sent (the fast
approach must stop above the key: SafetyViolation otherwise, nothing moves). Its fast retract
starts after lift-off, while the key is already settling, so it counts toward the settle pause.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from pianobot.physics.trajectory import Press, check_press, press_timing
from pianobot.plan.labtime import SAME_VACUUM_KPA
from pianobot.rig.errors import SafetyViolation
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

# Hover distances (m) closer than this are the same setting (vacuum levels: SAME_VACUUM_KPA,
# the one tolerance the plan's lab time counts vacuum changes with too).
SAME_DISTANCE_M = 1e-9


@dataclass(frozen=True)
class StationSettings:
    """How a keystroke is collected."""

    settle_s: float = 0.5  # sweep keystrokes: wait after the arm is back, before the window closes
    after_vacuum_change_s: float = 5.0  # from the command: regulator and jammed particles settle
    record_arm: bool = True
    record_mocap: bool = True


class Station:
    """Runs keystrokes on a set of devices; remembers vacuum level and hover position."""

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

    @property
    def hover(self) -> tuple[int, float] | None:
        """(note, distance_m) the arm hovers at, or None when unknown."""
        return self._hover

    @property
    def vacuum_kpa(self) -> float | None:
        """The settled vacuum level, or None when unknown (at start, after venting)."""
        return self._vacuum_kpa

    def forget_position(self) -> None:
        """After a reconnect or a stop the arm may be anywhere: hover again before the next press."""
        self._hover = None

    def forget_vacuum(self) -> None:
        """After venting, the next keystroke sets the level again."""
        self._vacuum_kpa = None
        self._vacuum_measured_kpa = None

    def set_vacuum(self, vacuum_kpa: float) -> float:
        """Set the level unless it is set already and wait until it settled; return the measured level.

        The wait is `after_vacuum_change_s` from the command: `Vacuum.set_kpa` may have waited
        for the regulator already, the jammed particles need the rest.
        """
        if self._vacuum_kpa is not None and math.isclose(self._vacuum_kpa, vacuum_kpa, abs_tol=SAME_VACUUM_KPA):
            return float(self._vacuum_measured_kpa if self._vacuum_measured_kpa is not None else vacuum_kpa)
        t_command_s = self.clock.now()
        self._vacuum_kpa = None  # unknown until the regulator reports back
        self._vacuum_measured_kpa = self.vacuum.set_kpa(vacuum_kpa)
        waited_s = self.clock.now() - t_command_s
        self.clock.sleep(self.settings.after_vacuum_change_s - waited_s)
        self._vacuum_kpa = float(vacuum_kpa)
        return float(self._vacuum_measured_kpa)

    def move_to_key(self, note: int, distance_m: float) -> float:
        """Hover `distance_m` above `note`'s key unless already there; return the seconds it took."""
        hover = (int(note), float(distance_m))
        if self._hover is not None and self._hover[0] == hover[0] and math.isclose(
            self._hover[1], hover[1], abs_tol=SAME_DISTANCE_M
        ):
            return 0.0
        # Forget first: if the move fails half-way the arm is somewhere in between.
        self._hover = None
        t0_s = self.clock.now()
        self.arm.move_to_key(hover[0], hover[1])
        self._hover = hover
        return self.clock.now() - t0_s

    def keystroke(
        self, trial: TrialLike, attempt: int = 1, *, start_at_s: float | None = None,
        settle_s: float | None = None,
    ) -> KeystrokeResult:
        """Set the vacuum, hover over the key, press and collect (the sweep's sequence).

        `settle_s` defaults to the station's pause after a press. Raises whatever the devices
        raise (ConnectionLost, SafetyStop, SafetyViolation); the runner decides what to do.
        """
        self.set_vacuum(trial.vacuum_kpa)
        self.move_to_key(trial.note, trial.distance_m)
        return self.press(trial, attempt, start_at_s=start_at_s,
                          settle_s=self.settings.settle_s if settle_s is None else settle_s)

    def press(
        self, trial: TrialLike, attempt: int = 1, *, start_at_s: float | None = None, settle_s: float = 0.0
    ) -> KeystrokeResult:
        """Press the key the arm hovers over, starting at `start_at_s` on the rig clock.

        The arm must hover over `trial.note` at `trial.distance_m` and the vacuum must be at
        `trial.vacuum_kpa` (else SafetyViolation: nothing moved). A start time already past
        starts at once; the record's `t_start_s` says when the press really started. Returns
        when the arm is back up plus `settle_s`.
        """
        self._check_ready(trial)
        press = trial.press()
        try:
            check_press(press)
        except ValueError as exc:
            raise SafetyViolation(f"press of trial {trial.index} refused: {exc}") from None
        if start_at_s is not None:
            self.clock.sleep(start_at_s - self.clock.now())
        if self.before_press is not None:
            self.before_press(trial, attempt)
        try:
            record = self.arm.press(press, trial.note)
        except BaseException:
            self._hover = None
            raise
        # The key has been free since lift-off: a fast retract is part of the pause.
        retract_s = press_timing(press).retract.duration_s if press.retract_m > 0.0 else 0.0
        self.clock.sleep(settle_s - retract_s)
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

    def _check_ready(self, trial: TrialLike) -> None:
        hover = self._hover
        if hover is None or hover[0] != trial.note or not math.isclose(
            hover[1], trial.distance_m, abs_tol=SAME_DISTANCE_M
        ):
            where = "an unknown position" if hover is None else f"note {hover[0]} at {hover[1]:g} m"
            raise SafetyViolation(
                f"press of note {trial.note} at {trial.distance_m:g} m refused: the arm hovers at "
                f"{where}; call move_to_key first"
            )
        level = self._vacuum_kpa
        if level is None or not math.isclose(level, trial.vacuum_kpa, abs_tol=SAME_VACUUM_KPA):
            now = "unknown" if level is None else f"{level:g} kPa"
            raise SafetyViolation(
                f"press at {trial.vacuum_kpa:g} kPa refused: the vacuum is {now}; call set_vacuum first"
            )


class Rig:
    """Devices, clock and keystroke sequence of one rig, as `open_rig` yields it.

    Sweeps call `keystroke(trial, attempt)`; players set the vacuum (`set_vacuum`), move
    (`move_to_key`, returns its duration) and press at planned times (`press_at`).
    `reconnect()` re-opens the arm's link after a ConnectionLost; `clear_stop()` is called when
    an operator resumes a run that a protective stop ended; `make_safe()` retracts the arm and
    vents the vacuum. Every keystroke result carries what the backend adds (for the sim the
    world's truth trace and key features).
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
        prepare: Callable[[Sequence[TrialLike]], None] | None = None,
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
        self._prepare = prepare

    @property
    def simulated(self) -> bool:
        return self.kind == "sim"

    @property
    def batches(self) -> bool:
        """Whether the rig can work out blocks of keystrokes ahead (`prepare`): the sim can."""
        return self._prepare is not None

    def prepare(self, trials: Sequence[TrialLike]) -> None:
        """Work out the next keystrokes ahead, all at once (the sim's physics); no motion.

        The keystrokes still run one by one through `keystroke`, with the same faults, retries
        and results as without; a real rig has nothing to prepare and keeps its pace.
        """
        if self._prepare is not None:
            self._prepare(trials)

    @property
    def warnings(self) -> tuple[str, ...]:
        """What the devices found when they were opened (e.g. the UR's speed slider below
        100 %): to be shown before any motion."""
        return tuple(w for device in (self.arm, self.vacuum)
                     for w in getattr(device, "warnings", ()))

    def keystroke(
        self, trial: TrialLike, attempt: int = 1, *, start_at_s: float | None = None,
        settle_s: float | None = None,
    ) -> KeystrokeResult:
        """Run one keystroke (attempt numbers start at 1): vacuum, hover, press, settle, collect.

        `start_at_s` delays the press to a rig-clock time; `settle_s` replaces the rig's pause
        after the press (default: the rig file's `settle_s.between_presses_s`).
        """
        result = self.station.keystroke(trial, attempt, start_at_s=start_at_s, settle_s=settle_s)
        return self._finished(result)

    def press_at(
        self, trial: TrialLike, attempt: int = 1, *, start_at_s: float | None = None, settle_s: float = 0.0
    ) -> KeystrokeResult:
        """Press the key the arm hovers over, starting at rig-clock time `start_at_s`.

        No vacuum change and no move: call `set_vacuum` and `move_to_key` first (else
        SafetyViolation, nothing moves). Returns when the arm is back up (plus `settle_s`), so
        the next lateral move can overlap the key's return. A start already past starts at
        once: compare `result.press.t_start_s` with the plan.
        """
        return self._finished(self.station.press(trial, attempt, start_at_s=start_at_s, settle_s=settle_s))

    def set_vacuum(self, vacuum_kpa: float) -> float:
        """Set the finger's vacuum and wait until it settled (no-op when already set); measured kPa."""
        return self.station.set_vacuum(vacuum_kpa)

    def move_to_key(self, note: int, distance_m: float) -> float:
        """Hover `distance_m` above `note`'s key; the seconds the move took (0 when already there)."""
        return self.station.move_to_key(note, distance_m)

    def _finished(self, result: KeystrokeResult) -> KeystrokeResult:
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
