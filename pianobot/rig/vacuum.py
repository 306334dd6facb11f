"""The vacuum regulator that stiffens the particle-jamming finger, in three flavours.

- `AnalogVacuum` drives an electro-pneumatic regulator from a UR analog output (`RTDEIOInterface.
  setAnalogOutputVoltage`, a ratio of the 0–10 V span) through a linear kPa ↔ ratio calibration,
  optionally reads the regulator's monitor output back on a UR analog input and waits until it
  settles.
- `ManualVacuum` asks the operator to set a hand regulator and confirm (a terminal is required).
- `CommandedVacuum` is for lab rigs without a regulator (a rigid finger): it only records levels.

Pressures are gauge kPa, <= 0 (more negative = more vacuum = a stiffer finger).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from pianobot.rig.errors import DeviceUnavailable, RigError, SafetyViolation
from pianobot.rig.protocols import Clock

# Regulator monitor outputs swing over the same 0–10 V span the command uses.
ANALOG_INPUT_FULL_SCALE_V = 10.0
POLL_PERIOD_S = 0.05
STABLE_READINGS = 3  # consecutive in-tolerance readings that count as "settled"


class AnalogOutput(Protocol):
    """The part of `rtde_io.RTDEIOInterface` a regulator needs."""

    def setAnalogOutputVoltage(self, output_id: int, voltage_ratio: float) -> bool: ...  # noqa: N802


class AnalogInput(Protocol):
    """The part of `rtde_receive.RTDEReceiveInterface` used for the read-back."""

    def getStandardAnalogInput0(self) -> float: ...  # noqa: N802

    def getStandardAnalogInput1(self) -> float: ...  # noqa: N802


@dataclass(frozen=True)
class LinearCalibration:
    """kPa = kpa_at_ratio_0 + ratio · (kpa_at_ratio_1 − kpa_at_ratio_0), ratio in [0, 1]."""

    kpa_at_ratio_0: float
    kpa_at_ratio_1: float

    def __post_init__(self) -> None:
        if self.kpa_at_ratio_0 == self.kpa_at_ratio_1:
            raise ValueError("kpa_at_ratio_0 and kpa_at_ratio_1 must differ")

    def ratio(self, vacuum_kpa: float) -> float:
        """The output ratio for a level; SafetyViolation outside the regulator's range."""
        ratio = (vacuum_kpa - self.kpa_at_ratio_0) / (self.kpa_at_ratio_1 - self.kpa_at_ratio_0)
        if not -1e-9 <= ratio <= 1 + 1e-9:
            low, high = sorted((self.kpa_at_ratio_0, self.kpa_at_ratio_1))
            raise SafetyViolation(
                f"vacuum {vacuum_kpa:g} kPa is outside the regulator range [{low:g}, {high:g}] kPa"
            )
        return min(max(ratio, 0.0), 1.0)

    def kpa(self, ratio: float) -> float:
        """The level a ratio stands for."""
        return self.kpa_at_ratio_0 + ratio * (self.kpa_at_ratio_1 - self.kpa_at_ratio_0)


class AnalogVacuum:
    """A regulator on a UR analog output, with optional read-back (implements `Vacuum`).

    With read-back, `set_kpa` waits until the reading stays within `tolerance_kpa` of the level
    (RigError with the last reading after `settle_timeout_s`). Without it, `set_kpa` returns the
    commanded level at once; the rig's `settle_s.after_vacuum_change_s` pause covers settling.
    """

    def __init__(
        self,
        calibration: LinearCalibration,
        *,
        io: AnalogOutput,
        clock: Clock,
        output_channel: int = 0,
        input_channel: int | None = None,
        receive: AnalogInput | None = None,
        settle_timeout_s: float = 10.0,
        tolerance_kpa: float = 2.0,
    ) -> None:
        if output_channel not in (0, 1):
            raise DeviceUnavailable(f"analog output channel must be 0 or 1, got {output_channel}")
        if input_channel is not None and input_channel not in (0, 1):
            raise DeviceUnavailable(f"analog input channel must be 0 or 1, got {input_channel}")
        if input_channel is not None and receive is None:
            raise DeviceUnavailable("vacuum read-back needs the RTDE receive interface")
        self.calibration = calibration
        self._io = io
        self._receive = receive
        self._clock = clock
        self.output_channel = output_channel
        self.input_channel = input_channel
        self.settle_timeout_s = settle_timeout_s
        self.tolerance_kpa = tolerance_kpa
        self._commanded_kpa: float | None = None

    def read_kpa(self) -> float | None:
        """The regulator's monitor reading in kPa, or None without read-back."""
        if self.input_channel is None or self._receive is None:
            return None
        if self.input_channel == 0:
            volts = self._receive.getStandardAnalogInput0()
        else:
            volts = self._receive.getStandardAnalogInput1()
        return self.calibration.kpa(volts / ANALOG_INPUT_FULL_SCALE_V)

    def _command(self, vacuum_kpa: float) -> None:
        ratio = self.calibration.ratio(vacuum_kpa)
        if not self._io.setAnalogOutputVoltage(self.output_channel, ratio):
            raise RigError(
                f"the controller refused analog output {self.output_channel} = {ratio:.3f} "
                f"({vacuum_kpa:g} kPa); is the RTDE I/O interface connected?"
            )
        self._commanded_kpa = vacuum_kpa

    def set_kpa(self, vacuum_kpa: float) -> float:
        """Command a level and wait until the read-back settles; return the measured level."""
        self._command(vacuum_kpa)
        if self.input_channel is None:
            return vacuum_kpa
        deadline = self._clock.now() + self.settle_timeout_s
        stable = 0
        last = None
        while True:
            last = self.read_kpa()
            assert last is not None
            stable = stable + 1 if abs(last - vacuum_kpa) <= self.tolerance_kpa else 0
            if stable >= STABLE_READINGS:
                return last
            if self._clock.now() >= deadline:
                raise RigError(
                    f"vacuum did not settle at {vacuum_kpa:g} ± {self.tolerance_kpa:g} kPa within "
                    f"{self.settle_timeout_s:g} s (last reading {last:.1f} kPa)"
                )
            self._clock.sleep(POLL_PERIOD_S)

    def vent(self) -> None:
        """Command atmospheric pressure (0 kPa). Never raises."""
        try:
            self._command(0.0)
        except Exception:  # venting is a best effort on the way out
            pass

    def describe(self) -> dict[str, Any]:
        """Channels and calibration, for run metadata."""
        return {
            "kind": "vacuum",
            "mode": "ur-analog",
            "output_channel": self.output_channel,
            "input_channel": self.input_channel,
            "kpa_at_ratio_0": self.calibration.kpa_at_ratio_0,
            "kpa_at_ratio_1": self.calibration.kpa_at_ratio_1,
            "tolerance_kpa": self.tolerance_kpa,
            "settle_timeout_s": self.settle_timeout_s,
        }


def _stdin_is_tty() -> bool:
    return sys.stdin is not None and sys.stdin.isatty()


def _notify_stderr(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


class ManualVacuum:
    """The operator sets a hand regulator when asked (implements `Vacuum`).

    Args:
        ask: shows a prompt and returns the operator's answer (default `input`).
        interactive: whether an operator can answer (default: stdin is a terminal).
        notify: prints a message that needs no answer (default: stderr).
    """

    def __init__(
        self,
        *,
        ask: Callable[[str], str] = input,
        interactive: Callable[[], bool] = _stdin_is_tty,
        notify: Callable[[str], None] = _notify_stderr,
    ) -> None:
        self._ask = ask
        self._interactive = interactive
        self._notify = notify
        self._level_kpa: float | None = None

    def set_kpa(self, vacuum_kpa: float) -> float:
        """Ask the operator to set the level; return their gauge reading (or the level)."""
        if vacuum_kpa > 0:
            raise SafetyViolation(f"vacuum must be <= 0 kPa (gauge), got {vacuum_kpa:g}")
        if self._level_kpa == vacuum_kpa:
            return vacuum_kpa
        if not self._interactive():
            raise DeviceUnavailable(
                "vacuum mode 'manual' needs an operator at a terminal (stdin is not a TTY); "
                "run interactively or use vacuum mode 'ur-analog'"
            )
        prompt = (
            f"Set the vacuum regulator to {vacuum_kpa:g} kPa, then press Enter "
            "(or type the gauge reading in kPa): "
        )
        while True:
            try:
                answer = self._ask(prompt).strip()
            except EOFError as exc:
                raise DeviceUnavailable("the operator's terminal closed (end of input)") from exc
            if not answer:
                measured = vacuum_kpa
                break
            try:
                measured = float(answer)
                break
            except ValueError:
                prompt = f"Not a number: {answer!r}. Gauge reading in kPa (or Enter): "
        self._level_kpa = vacuum_kpa
        return measured

    def vent(self) -> None:
        """Remind the operator to vent the finger. Never raises (and never waits)."""
        try:
            if self._level_kpa not in (None, 0.0):
                self._notify("Vent the finger: set the vacuum regulator to 0 kPa.")
        except Exception:  # venting is a best effort on the way out
            pass
        self._level_kpa = None

    def describe(self) -> dict[str, Any]:
        """Mode only: levels are whatever the operator set."""
        return {"kind": "vacuum", "mode": "manual"}


class CommandedVacuum:
    """A lab rig without a regulator: levels are recorded, nothing is driven (`Vacuum`)."""

    def __init__(self) -> None:
        self.level_kpa = 0.0

    def set_kpa(self, vacuum_kpa: float) -> float:
        """Record the level and return it (nothing to wait for)."""
        self.level_kpa = vacuum_kpa
        return vacuum_kpa

    def vent(self) -> None:
        """Back to 0 kPa. Never raises."""
        self.level_kpa = 0.0

    def describe(self) -> dict[str, Any]:
        """Mode only."""
        return {"kind": "vacuum", "mode": "none", "note": "no regulator: levels not driven"}
