"""The TCP trace of a press: z samples with controller timestamps, mapped onto the run clock.

The receive interface is polled faster than the controller rate and a sample is kept only when
the controller timestamp changes, so the trace has one sample per controller cycle (500 Hz on a
CB3/e-Series). The controller clock is mapped onto the run clock by the smallest observed
(read time − controller time): a read can only come after the controller produced the sample,
so the least-delayed read is the best estimate of the offset.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pianobot.rig.protocols import Clock, Trace


class TcpRecorder:
    """TCP z samples with controller timestamps, and the run-clock time each was read."""

    def __init__(self, receive: Any, clock: Clock) -> None:
        self._receive = receive
        self._clock = clock
        self._last_ts: float | None = None
        self.ctrl_s: list[float] = []
        self.read_s: list[float] = []
        self.z_m: list[float] = []
        self.min_scaling = math.inf

    def sample(self) -> None:
        ts = float(self._receive.getTimestamp())
        if ts == self._last_ts:
            return
        read_s = self._clock.now()
        pose = self._receive.getActualTCPPose()
        self._last_ts = ts
        self.ctrl_s.append(ts)
        self.read_s.append(read_s)
        self.z_m.append(float(pose[2]))
        scaling = self._receive.getSpeedScaling()
        if scaling is not None:
            self.min_scaling = min(self.min_scaling, float(scaling))

    def trace(self, z_start_m: float) -> Trace | None:
        """Downward displacement from the hover height, on the run clock."""
        if not self.ctrl_s:
            return None
        ctrl = np.asarray(self.ctrl_s, dtype=np.float64)
        # A read can only come after the controller produced the sample: the least-delayed read
        # gives the best controller → run clock offset.
        offset_s = float(np.min(np.asarray(self.read_s) - ctrl))
        x0_m = z_start_m - np.asarray(self.z_m, dtype=np.float64)
        return Trace(t_s=ctrl + offset_s, x0_m=x0_m, source="arm")
