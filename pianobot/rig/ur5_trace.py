"""The TCP trace of a press: one sample per controller cycle, timestamp and pose from one package.

ur_rtde's receive thread writes every field of an RTDE package under one lock, and each getter
takes that lock; so reading the timestamp, then the pose, then the timestamp again, and keeping
the pose only when both timestamps agree, proves the pose came from the package that timestamp
belongs to (a read that straddles a new package is retried). Each controller cycle is kept
once. `startFileRecording` is no alternative: its thread samples on the host's clock (a cycle
can be written twice or skipped) and reads the fields of a row under separate locks.

The controller clock is mapped onto the run clock by the smallest observed (read time −
controller time): a read can only come after the controller produced the sample, so the
least-delayed read is the best estimate of the offset. Cycles the host missed (a loaded
machine) are gaps in the trace, counted in `missed_cycles`; nothing is interpolated.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pianobot.rig.protocols import Clock, Trace

READ_ATTEMPTS = 3  # a new package during every attempt: take the cycle at the next poll


class TcpRecorder:
    """TCP z samples with controller timestamps, and the run-clock time each was read."""

    def __init__(self, receive: Any, clock: Clock) -> None:
        self._receive = receive
        self._clock = clock
        self._last_ts: float | None = None
        self.ctrl_s: list[float] = []
        self.read_s: list[float] = []
        self.z_m: list[float] = []
        self.torn_reads = 0  # reads that straddled a package and were retried

    def sample(self) -> None:
        """Record the newest controller cycle, if it is new."""
        receive = self._receive
        for _ in range(READ_ATTEMPTS):
            ts = float(receive.getTimestamp())
            if ts == self._last_ts:
                return
            read_s = self._clock.now()
            pose = receive.getActualTCPPose()
            if float(receive.getTimestamp()) != ts:
                self.torn_reads += 1
                continue
            self._last_ts = ts
            self.ctrl_s.append(ts)
            self.read_s.append(read_s)
            self.z_m.append(float(pose[2]))
            return

    @property
    def period_s(self) -> float | None:
        """The controller's cycle as seen in the trace (the smallest step between samples)."""
        if len(self.ctrl_s) < 2:
            return None
        steps = np.diff(np.asarray(self.ctrl_s))
        steps = steps[steps > 0]
        return float(np.min(steps)) if steps.size else None

    @property
    def missed_cycles(self) -> int:
        """Controller cycles inside the trace that the host did not read in time."""
        period = self.period_s
        if period is None:
            return 0
        steps = np.diff(np.asarray(self.ctrl_s))
        return int(np.sum(np.round(steps / period) - 1))

    @property
    def offset_s(self) -> float | None:
        """Run-clock time minus controller time (the least-delayed read's)."""
        if not self.ctrl_s:
            return None
        return float(np.min(np.asarray(self.read_s) - np.asarray(self.ctrl_s)))

    def trace(self, z_start_m: float) -> Trace | None:
        """Downward displacement from the hover height, on the run clock."""
        offset_s = self.offset_s
        if offset_s is None:
            return None
        ctrl = np.asarray(self.ctrl_s, dtype=np.float64)
        x0_m = z_start_m - np.asarray(self.z_m, dtype=np.float64)
        return Trace(t_s=ctrl + offset_s, x0_m=x0_m, source="arm")
