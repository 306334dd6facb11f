"""The vacuum regulator that stiffens the particle-jamming finger, in three flavours.

- `AnalogVacuum` drives an electronic vacuum regulator from a UR standard analog output, in the
  domain its command input needs: voltage (`RTDEIOInterface.setAnalogOutputVoltage`, a ratio of
  the UR's 0-10 V) or current (`setAnalogOutputCurrent`, a ratio of 4-20 mA). The regulator's
  signal span and the pressures at its two ends come from the rig file (`SignalSpan`): an SMC
  ITV2090 spans 0 to -80 kPa over 0-10 V, others reach -100 kPa, so no span is assumed. An
  optional monitor output on a UR analog input is read back until the level settles.
- `ManualVacuum` asks the operator to set a hand regulator and confirm (a terminal is required).
- `CommandedVacuum` is for lab rigs without a regulator (a rigid finger): it only records levels.

Pressures are gauge kPa, <= 0 (more negative = more vacuum = a stiffer finger).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from pianobot.rig.errors import ConnectionLost, DeviceUnavailable, RigError, SafetyViolation
from pianobot.rig.protocols import Clock
from pianobot.spec.rig import SIGNAL_UNIT, UR_ANALOG_SPAN

POLL_PERIOD_S = 0.05
STABLE_READINGS = 3  # consecutive in-tolerance readings that count as "settled"
# What a UR standard analog output drives over its ratio 0..1 (V or mA).


class AnalogOutput(Protocol):
    """The part of `rtde_io.RTDEIOInterface` a regulator needs."""

    def setAnalogOutputVoltage(self, output_id: int, voltage_ratio: float, /) -> bool: ...  # noqa: N802

    def setAnalogOutputCurrent(self, output_id: int, current_ratio: float, /) -> bool: ...  # noqa: N802


class AnalogInput(Protocol):
    """The part of `rtde_receive.RTDEReceiveInterface` used for the read-back."""

    def isConnected(self) -> bool: ...  # noqa: N802

    def getStandardAnalogInput0(self) -> float: ...  # noqa: N802

    def getStandardAnalogInput1(self) -> float: ...  # noqa: N802


@dataclass(frozen=True)
class SignalSpan:
    """A linear signal ↔ pressure map: `signal_span` (V or mA) carries `kpa_span` (kPa)."""

    signal: str  # "voltage" | "current"
    signal_span: tuple[float, float]
    kpa_span: tuple[float, float]

    def __post_init__(self) -> None:
        if self.signal not in UR_ANALOG_SPAN:
            raise ValueError(f"signal must be voltage or current, got {self.signal!r}")
        if self.signal_span[0] == self.signal_span[1] or self.kpa_span[0] == self.kpa_span[1]:
            raise ValueError("signal_span and kpa_span must each have two different ends")

    @property
    def unit(self) -> str:
        return SIGNAL_UNIT[self.signal]

    def value_for(self, vacuum_kpa: float) -> float:
        """The signal (V or mA) for a level; SafetyViolation beyond the regulator's range.

        A level between atmospheric (0 kPa) and the span's end nearest to it gets that end:
        the regulator cannot get closer to atmospheric pressure (an SMC ITV2090 starts at
        -1.3 kPa), and asking for 0 kPa must always be possible (venting).
        """
        k0, k1 = self.kpa_span
        frac = (vacuum_kpa - k0) / (k1 - k0)
        near_zero = min(abs(k0), abs(k1))
        if -near_zero - 1e-9 <= vacuum_kpa <= 1e-9:
            frac = 0.0 if abs(k0) <= abs(k1) else 1.0
        if not -1e-9 <= frac <= 1 + 1e-9:
            low, high = sorted(self.kpa_span)
            raise SafetyViolation(
                f"vacuum {vacuum_kpa:g} kPa is outside the regulator range [{low:g}, {high:g}] kPa"
            )
        frac = min(max(frac, 0.0), 1.0)
        s0, s1 = self.signal_span
        return s0 + frac * (s1 - s0)

    def kpa_for(self, value: float) -> float:
        """The level a signal (V or mA) stands for."""
        s0, s1 = self.signal_span
        k0, k1 = self.kpa_span
        return k0 + (value - s0) / (s1 - s0) * (k1 - k0)

    def ur_ratio(self, value: float) -> float:
        """The ratio of the UR output's span that drives `value` (V or mA) in this domain."""
        lo, hi = UR_ANALOG_SPAN[self.signal]
        return min(max((value - lo) / (hi - lo), 0.0), 1.0)

    def text(self) -> str:
        s0, s1 = self.signal_span
        k0, k1 = self.kpa_span
        return f"{s0:g}-{s1:g} {self.unit} = {k0:g} to {k1:g} kPa"


class AnalogVacuum:
    """A regulator on a UR analog output, with optional read-back (implements `Vacuum`).

    With a monitor, `set_kpa` waits until the reading stays within `tolerance_kpa` of the level
    (RigError with the last reading after `settle_timeout_s`). Without it, `set_kpa` returns the
    commanded level at once; the rig's `settle_s.after_vacuum_change_s` pause covers settling.
    """

    def __init__(
        self,
        command: SignalSpan,
        *,
        io: AnalogOutput,
        clock: Clock,
        output_channel: int = 0,
        monitor: SignalSpan | None = None,
        input_channel: int | None = None,
        receive: AnalogInput | None = None,
        settle_timeout_s: float = 10.0,
        tolerance_kpa: float = 2.0,
    ) -> None:
        if output_channel not in (0, 1):
            raise DeviceUnavailable(f"analog output channel must be 0 or 1, got {output_channel}")
        if (monitor is None) != (input_channel is None):
            raise DeviceUnavailable("a vacuum monitor needs both its span and its input channel")
        if input_channel is not None and input_channel not in (0, 1):
            raise DeviceUnavailable(f"analog input channel must be 0 or 1, got {input_channel}")
        if input_channel is not None and receive is None:
            raise DeviceUnavailable("vacuum read-back needs the RTDE receive interface")
        self.command = command
        self.monitor = monitor
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
        if self.monitor is None or self._receive is None:
            return None
        try:
            if not self._receive.isConnected():  # ur_rtde would hand back the last reading
                raise ConnectionLost("vacuum read-back: the RTDE receive link is down")
            if self.input_channel == 0:
                value = self._receive.getStandardAnalogInput0()
            else:
                value = self._receive.getStandardAnalogInput1()
        except RuntimeError as exc:
            raise ConnectionLost(f"vacuum read-back: {exc}") from exc
        return self.monitor.kpa_for(float(value))

    def _command(self, vacuum_kpa: float) -> None:
        value = self.command.value_for(vacuum_kpa)
        ratio = self.command.ur_ratio(value)
        try:
            if self.command.signal == "voltage":
                sent = self._io.setAnalogOutputVoltage(self.output_channel, ratio)
            else:
                sent = self._io.setAnalogOutputCurrent(self.output_channel, ratio)
        except RuntimeError as exc:  # ur_rtde raises when its write or its reconnect fails
            raise ConnectionLost(f"vacuum I/O link: {exc}") from exc
        if not sent:
            raise RigError(
                f"the controller refused analog output {self.output_channel} = {value:.2f} "
                f"{self.command.unit} ({vacuum_kpa:g} kPa); is the RTDE I/O interface connected?"
            )
        self._commanded_kpa = vacuum_kpa

    def set_kpa(self, vacuum_kpa: float) -> float:
        """Command a level and wait until the read-back settles; return the measured level."""
        self._command(vacuum_kpa)
        if self.monitor is None:
            return vacuum_kpa
        # The level the regulator will hold (a level nearer to atmospheric than its span gets
        # the span's end).
        target = self.command.kpa_for(self.command.value_for(vacuum_kpa))
        deadline = self._clock.now() + self.settle_timeout_s
        stable = 0
        while True:
            last = self.read_kpa()
            assert last is not None
            stable = stable + 1 if abs(last - target) <= self.tolerance_kpa else 0
            if stable >= STABLE_READINGS:
                return last
            if self._clock.now() >= deadline:
                raise RigError(
                    f"vacuum did not settle at {vacuum_kpa:g} ± {self.tolerance_kpa:g} kPa within "
                    f"{self.settle_timeout_s:g} s (last reading {last:.1f} kPa); check the "
                    f"regulator's signal ({self.command.text()}) and monitor "
                    f"({self.monitor.text()}) against its data sheet"
                )
            self._clock.sleep(POLL_PERIOD_S)

    def vent(self) -> None:
        """Command atmospheric pressure (0 kPa). Never raises."""
        try:
            self._command(0.0)
        except Exception:  # venting is a best effort on the way out
            pass

    def describe(self) -> dict[str, Any]:
        """Signal, spans and channels, for run metadata."""
        return {
            "kind": "vacuum",
            "mode": "ur-analog",
            "output_channel": self.output_channel,
            "signal": self.command.signal,
            "signal_span": list(self.command.signal_span),
            "kpa_span": list(self.command.kpa_span),
            "input_channel": self.input_channel,
            "monitor": None if self.monitor is None else {
                "signal": self.monitor.signal, "signal_span": list(self.monitor.signal_span),
                "kpa_span": list(self.monitor.kpa_span)},
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
