"""Run clocks: virtual time for the simulated rig, monotonic wall time for hardware."""

from __future__ import annotations

import time


class VirtualClock:
    """Simulated lab time: `sleep` advances it instantly, so a 2,000-trial sweep takes seconds.

    With `realtime=True` it also sleeps for real, so a simulated sweep runs at lab speed (for
    demos and for testing a progress display or Ctrl-C by hand).
    """

    def __init__(self, start_s: float = 0.0, *, realtime: bool = False) -> None:
        self._t_s = float(start_s)
        self.realtime = realtime

    def now(self) -> float:
        return self._t_s

    def sleep(self, seconds: float) -> None:
        """Advance by `seconds` (negative or NaN durations are ignored)."""
        if not seconds > 0:
            return
        if self.realtime:
            time.sleep(seconds)
        self._t_s += seconds

    def describe(self) -> dict[str, object]:
        return {"kind": "virtual", "realtime": self.realtime}


class WallClock:
    """Seconds since the clock was made, from the monotonic clock (immune to NTP steps)."""

    def __init__(self) -> None:
        self._origin = time.monotonic()

    def now(self) -> float:
        return time.monotonic() - self._origin

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)

    def describe(self) -> dict[str, object]:
        return {"kind": "wall"}
