"""An electronic vacuum regulator wired to the emulated UR's analog I/O (SMC ITV209x-like).

The regulator takes a command signal in one domain (0-10 V, 0-5 V or 4-20 mA, as ordered),
regulates a vacuum between two levels over that signal span (the ITV2090's is 0 to -80 kPa
gauge; others reach -100 kPa), follows its set point like a first-order lag, and reports the
pressure on a monitor output (1-5 V on the ITV series) wired to a UR analog input.

The UR side: each standard analog output is in the current (4-20 mA) or voltage (0-10 V)
domain; RTDE writes a ratio of that span (`standard_analog_output_0/1`) together with a
domain bit per output (`standard_analog_output_type`, bit n for output n). A command in the
wrong domain is not a valid signal for the regulator: it then holds atmospheric pressure
(a modelling choice — a real one reads nonsense; either way the read-back disagrees).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

VOLTAGE, CURRENT = "voltage", "current"
UR_SPAN = {VOLTAGE: (0.0, 10.0), CURRENT: (4.0, 20.0)}  # V or mA over the ratio 0..1


def ur_value(domain: str, ratio: float) -> float:
    """Volts or milliamps a UR analog output drives for a ratio of its span."""
    low, high = UR_SPAN[domain]
    return low + min(max(ratio, 0.0), 1.0) * (high - low)


@dataclass
class VacuumRegulator:
    """Regulator parameters (defaults: an SMC ITV2090 with a 0-10 V input, 1-5 V monitor)."""

    output_channel: int = 0  # the UR analog output that commands it
    signal: str = VOLTAGE
    signal_span: tuple[float, float] = (0.0, 10.0)  # V or mA
    kpa_span: tuple[float, float] = (0.0, -80.0)  # kPa at the two ends of the signal span
    monitor_channel: int | None = 0  # the UR analog input its monitor output is wired to
    monitor_signal: str = VOLTAGE
    monitor_span: tuple[float, float] = (1.0, 5.0)
    tau_s: float = 0.3
    kpa: float = 0.0  # the pressure now

    def set_point_kpa(self, domain: str, value: float) -> float:
        """The level the regulator aims for, given what the UR output drives."""
        if domain != self.signal:
            return 0.0
        lo, hi = self.signal_span
        frac = min(max((value - lo) / (hi - lo), 0.0), 1.0)
        return self.kpa_span[0] + frac * (self.kpa_span[1] - self.kpa_span[0])

    def step(self, dt_s: float, domain: str, value: float) -> None:
        target = self.set_point_kpa(domain, value)
        self.kpa += (target - self.kpa) * (1.0 - math.exp(-dt_s / self.tau_s))

    def monitor_value(self) -> float:
        """Volts (or mA) on the monitor output for the pressure now."""
        k0, k1 = self.kpa_span
        frac = min(max((self.kpa - k0) / (k1 - k0), 0.0), 1.0)
        lo, hi = self.monitor_span
        return lo + frac * (hi - lo)
