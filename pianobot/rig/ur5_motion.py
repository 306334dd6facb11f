"""One guarded moveL on the UR5: sent only over live links, waited for, diagnosed.

A command sent to a control interface whose link is down is lost, and ur_rtde then waits for
its answer for up to 300 s; so nothing goes out unless both links are up (ur_rtde can report
its control link up after a failed background reconnect, so a dropped receive link counts as
the network being down). Each moveL is sent asynchronously; its end is the control script's
async operation id moving on with the "running" bit clear (`getAsyncOperationProgressEx`; the
old `getAsyncOperationProgress` is deprecated). Meanwhile the receive interface is sampled once
per controller cycle (`TcpRecorder`).

A move is declared stalled only when its *trajectory* time — wall time × the combined speed
scaling, which the pendant's slider and the trajectory limiter lower and a pause holds at 0 —
exceeds the profile's duration by a margin, so a slow slider never reads as a stall. When the
control stream says the move ended, the receive stream (another connection, a cycle or two
behind) is waited for before the arrival is checked.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from pianobot.physics.trajectory import move_profile
from pianobot.rig.errors import ConnectionLost, RigError, SafetyViolation
from pianobot.rig.protocols import Clock
from pianobot.rig.ur5_link import quietly
from pianobot.rig.ur5_session import Links
from pianobot.rig.ur5_status import failure, read_status, settled_status
from pianobot.rig.ur5_trace import TcpRecorder

Pose = list[float]
STOP_DECELERATION_MPS2 = 2.0
AT_TARGET_M = 0.0005  # a move that ends further than this from its target stopped short
STALL_MARGIN_S = 2.0  # trajectory time beyond the profile's duration: the move stalled
SETTLE_CYCLES = 10  # after a move ends, the receive stream may lag the control stream this much


class GuardedMotion:
    """Sends one moveL at a time over `links` and returns when the arm is at the target."""

    def __init__(self, links: Links, clock: Clock) -> None:
        self.links = links
        self.clock = clock
        self.min_scaling = math.inf  # the lowest combined speed scaling seen while moving

    @property
    def period_s(self) -> float:
        assert self.links.rate_hz is not None
        return 1.0 / self.links.rate_hz

    def links_up(self) -> bool:
        """Both RTDE links up."""
        return bool(quietly(self.links.control, "isConnected")) and bool(
            quietly(self.links.receive, "isConnected"))

    def require_links(self, action: str) -> None:
        """The diagnosis (ConnectionLost, ...) unless the links are up."""
        if not self.links_up():
            raise self.fail(action)

    def fail(self, action: str) -> RigError:
        """The error for `action`, from a status both streams agree on."""
        return failure(action, settled_status(self.links.receive, self.links.control, self.period_s))

    def check_reach(self, pose: Sequence[float]) -> None:
        """SafetyViolation unless the controller finds the pose within its safety limits."""
        self.require_links("safety-limit check")
        try:
            within = self.links.control.isPoseWithinSafetyLimits(list(pose))
        except RuntimeError as exc:
            raise ConnectionLost(f"safety-limit check failed: {exc}") from exc
        if not within:
            status = settled_status(self.links.receive, self.links.control, self.period_s)
            if status.stopped or status.link_down or status.paused or status.script_stopped:
                raise failure("safety-limit check", status)  # ur_rtde answered False: not a no
            raise SafetyViolation(
                f"target {fmt_pose(pose)} is outside the robot's safety limits or reach"
            )

    def move(self, target: Pose, speed_mps: float, acceleration_mps2: float,
             recorder: TcpRecorder | None = None) -> None:
        """One asynchronous moveL (the target checked by the caller); returns on arrival."""
        action = f"moveL to {fmt_pose(target)}"
        self.require_links(action)
        try:
            start = self.links.receive.getActualTCPPose()
            expected_s = move_profile(math.dist(start[:3], target[:3]), speed_mps,
                                      acceleration_mps2).duration_s
            before = int(self.links.control.getAsyncOperationProgressEx().operationId())
            sent = self.links.control.moveL(list(target), speed_mps, acceleration_mps2, True)
        except RuntimeError as exc:
            raise ConnectionLost(f"{action}: {exc}") from exc
        if not sent:
            raise self.fail(action)
        try:
            self._wait(action, before, expected_s, recorder)
            self._await_arrival(action, target, recorder)
        except RuntimeError as exc:  # a dead link may raise instead of answering
            raise ConnectionLost(f"{action}: {exc}") from exc

    def _wait(self, action: str, before: int, expected_s: float,
              recorder: TcpRecorder | None) -> None:
        """Sample until the asynchronous move ends; diagnose stops, drops, pauses and stalls."""
        trajectory_s = 0.0  # wall time × combined speed scaling: how far the profile got
        last_s = t_sent = self.clock.now()
        while True:
            if recorder is not None:
                recorder.sample()
            operation = self.links.control.getAsyncOperationProgressEx()
            if operation.operationId() != before and not operation.isAsyncOperationRunning():
                break
            status = read_status(self.links.receive, self.links.control)
            if status.stopped or status.link_down or status.paused or status.script_stopped:
                raise self.fail(action)  # re-read until both streams tell the same story
            now = self.clock.now()
            scaling = status.speed_scaling_combined
            if scaling is None:
                scaling = (status.speed_slider or 1.0) * (status.speed_scaling or 1.0)
            self.min_scaling = min(self.min_scaling, scaling)
            trajectory_s += (now - last_s) * max(scaling, 0.0)
            last_s = now
            if trajectory_s > expected_s + STALL_MARGIN_S:
                self.stop()
                raise self.fail(f"{action} (no end after {now - t_sent:.1f} s)")
            self.clock.sleep(0.5 * self.period_s)

    def _await_arrival(self, action: str, target: Pose, recorder: TcpRecorder | None) -> None:
        """The move ended (control stream): wait for the receive stream to show the arrival."""
        deadline = self.clock.now() + SETTLE_CYCLES * self.period_s + 0.05
        while True:
            if recorder is not None:
                recorder.sample()
            reached = self.links.receive.getActualTCPPose()
            short_m = math.dist(reached[:3], target[:3])
            if short_m <= AT_TARGET_M:
                return
            if self.clock.now() > deadline:
                raise self.fail(f"{action} (stopped {1000 * short_m:.1f} mm short)")
            self.clock.sleep(0.5 * self.period_s)

    def stop(self) -> None:
        """stopL, if the links are up. Never raises."""
        if self.links_up():
            quietly(self.links.control, "stopL", STOP_DECELERATION_MPS2)


def fmt_pose(pose: Sequence[float]) -> str:
    return "[" + ", ".join(f"{v:.4f}" for v in pose) + "]"
