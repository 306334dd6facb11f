"""The UR5 arm over ur_rtde: calibrated key poses, guarded moveL presses, the TCP trace.

Geometry. The calibrated reference pose has the fingertip resting on the reference key (the B
left of middle C, 1.5 cm from the key's front edge, finger level). Every other key is that pose
shifted along the keyboard axis (a horizontal unit vector in the base frame, from the rig) by the
key-centre distance from `KeyboardGeometry`; the orientation never changes. Heights are base-
frame z (up); the recorded trace is converted to downward displacement from the hover pose, as
everywhere else in pianobot.

Motion. A press is: moveL to hover `distance` above the key, moveL down by distance + depth at
(v_down, a), hold, moveL back up at (v_up, a). Each moveL is sent asynchronously and the
receive interface is sampled at the controller rate meanwhile, so the trace carries controller
timestamps; the controller clock is mapped onto the run clock by the smallest observed
(read time − controller time), i.e. the least-delayed read.

Failures. ur_rtde answers `False` instead of raising; every False, every stall and every stop
seen while sampling is diagnosed (`ur5_link.failure`): stops raise SafetyStop (after
`make_safe`), a dropped link ConnectionLost. Every target is checked against the rig's workspace
box and `isPoseWithinSafetyLimits` before it is sent (SafetyViolation, nothing sent).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from pianobot.physics.keyboard import KeyboardGeometry
from pianobot.physics.trajectory import Press, move_profile
from pianobot.rig.errors import ConnectionLost, DeviceUnavailable, RigError, SafetyViolation
from pianobot.rig.protocols import Clock, PressRecord
from pianobot.rig.ur5_link import failure, open_control, open_receive, read_status
from pianobot.rig.ur5_trace import TcpRecorder
from pianobot.spec.rig import UR5Config

Pose = list[float]
DEFAULT_KEYBOARD_AXIS = (1.0, 0.0, 0.0)  # treble towards base +x unless the rig says otherwise
TRAVEL_VELOCITY_MPS = 0.1
TRAVEL_ACCELERATION_MPS2 = 0.5
STOP_DECELERATION_MPS2 = 2.0
AT_TARGET_M = 0.0005  # a move that ends further than this from its target stopped short
LATERAL_MOVE_M = 0.0005  # closer than this the arm is already over the key
STALL_MARGIN_S = 2.0  # beyond the profile duration (stretched by speed scaling) a move stalled


class UR5Arm:
    """The lab arm (implements the `Arm` protocol); ur_rtde objects come in through here.

    Args:
        config: the rig file's `ur5:` section (needs a calibrated `reference_pose`).
        control, receive: `RTDEControlInterface`, `RTDEReceiveInterface` (or fakes).
        io, dashboard: optional `RTDEIOInterface`, `DashboardClient` (reconnected, described).
        clock: the run clock.
        geometry: key positions relative to the reference key.
        keyboard_axis: base-frame horizontal direction from bass to treble.
    """

    def __init__(
        self,
        config: UR5Config,
        *,
        control: Any,
        receive: Any,
        io: Any = None,
        dashboard: Any = None,
        clock: Clock,
        geometry: KeyboardGeometry | None = None,
        keyboard_axis: Sequence[float] = DEFAULT_KEYBOARD_AXIS,
        travel_velocity_mps: float = TRAVEL_VELOCITY_MPS,
        travel_acceleration_mps2: float = TRAVEL_ACCELERATION_MPS2,
    ) -> None:
        if config.reference_pose is None:
            raise DeviceUnavailable(
                "the UR5 has no calibrated reference pose: run `pianobot rig calibrate RIGFILE`"
            )
        axis = np.asarray(keyboard_axis, dtype=np.float64)
        norm = float(np.linalg.norm(axis))
        if axis.shape != (3,) or norm == 0.0 or abs(axis[2]) > 1e-6 * norm:
            raise DeviceUnavailable(
                f"keyboard axis must be a horizontal 3-vector, got {list(keyboard_axis)}"
            )
        self.config = config
        self.control = control
        self.receive = receive
        self.io = io
        self.dashboard = dashboard
        self.clock = clock
        self.geometry = geometry or KeyboardGeometry(reference_note=config.reference_note)
        self.keyboard_axis = tuple(float(v) for v in axis / norm)
        self.travel_velocity_mps = travel_velocity_mps
        self.travel_acceleration_mps2 = travel_acceleration_mps2
        self.reference_pose: Pose = [float(v) for v in config.reference_pose]
        self._period_s = 1.0 / config.frequency_hz

    @classmethod
    def connect_to(
        cls,
        config: UR5Config,
        *,
        clock: Clock,
        receive_factory: Any = None,
        control_factory: Any = None,
        **options: Any,
    ) -> UR5Arm:
        """Open the RTDE receive and control interfaces (ur_rtde imported here, lazily).

        Raises DeviceUnavailable naming the host and the reason when the arm cannot be reached.
        The factories replace the SDK classes (tests pass fakes).
        """
        if config.reference_pose is None:  # fail before taking control of the arm
            raise DeviceUnavailable(
                "the UR5 has no calibrated reference pose: run `pianobot rig calibrate RIGFILE`"
            )
        host, rate, timeout = config.host, config.frequency_hz, config.connect_timeout_s
        receive = open_receive(host, rate, timeout, receive_factory)
        try:
            control = open_control(host, rate, timeout, control_factory)
        except RigError:
            _quietly(receive, "disconnect")
            raise
        return cls(config, control=control, receive=receive, clock=clock, **options)

    # -- poses -------------------------------------------------------------------------------
    def key_pose(self, note: int, height_m: float = 0.0) -> Pose:
        """TCP pose with the fingertip `height_m` above the surface of `note`'s key."""
        try:
            lateral_m = self.geometry.center_m(note)
        except ValueError as exc:
            raise SafetyViolation(str(exc)) from exc
        pose = list(self.reference_pose)
        for i in range(3):
            pose[i] += self.keyboard_axis[i] * lateral_m
        pose[2] += height_m
        return pose

    def check_target(self, pose: Sequence[float]) -> None:
        """SafetyViolation unless the pose is inside the workspace box and the robot's limits."""
        low, high = self.config.workspace_min_m, self.config.workspace_max_m
        for axis, value, lo, hi in zip("xyz", pose[:3], low, high, strict=True):
            if not lo - 1e-9 <= value <= hi + 1e-9:
                raise SafetyViolation(
                    f"target {axis} = {value:.4f} m is outside the workspace [{lo:g}, {hi:g}] m "
                    f"(pose {_fmt(pose)})"
                )
        try:
            within = self.control.isPoseWithinSafetyLimits(list(pose))
        except RuntimeError as exc:
            raise ConnectionLost(f"safety-limit check failed: {exc}") from exc
        if not within:
            raise SafetyViolation(
                f"target {_fmt(pose)} is outside the robot's safety limits or reach"
            )

    # -- motion ------------------------------------------------------------------------------
    def _fail(self, action: str) -> RigError:
        return failure(action, read_status(self.receive, self.control))

    def _move(self, target: Pose, speed_mps: float, acceleration_mps2: float,
              recorder: TcpRecorder | None = None) -> None:
        """One guarded asynchronous moveL; returns when the arm is at the target."""
        self.check_target(target)
        action = f"moveL to {_fmt(target)}"
        start = self.receive.getActualTCPPose()
        length_m = math.dist(start[:3], target[:3])
        expected_s = move_profile(length_m, speed_mps, acceleration_mps2).duration_s
        try:
            before = self.control.getAsyncOperationProgress()
            sent = self.control.moveL(list(target), speed_mps, acceleration_mps2, True)
        except RuntimeError as exc:
            raise ConnectionLost(f"{action}: {exc}") from exc
        if not sent:
            raise self._fail(action)
        try:
            self._wait_for_move(action, before, expected_s, recorder)
            reached = self.receive.getActualTCPPose()
        except RuntimeError as exc:  # a dead link may raise instead of answering
            raise ConnectionLost(f"{action}: {exc}") from exc
        if math.dist(reached[:3], target[:3]) > AT_TARGET_M:
            error = self._fail(f"{action} (stopped {1000 * math.dist(reached[:3], target[:3]):.1f}"
                               " mm short)")
            raise error

    def _wait_for_move(self, action: str, before: int, expected_s: float,
                       recorder: TcpRecorder | None) -> None:
        """Sample until the asynchronous move ends; diagnose stops, drops and stalls."""
        t_sent = self.clock.now()
        while True:
            if recorder is not None:
                recorder.sample()
            progress = self.control.getAsyncOperationProgress()
            if progress < 0 and progress != before:  # the script toggles -1/-2 when a move ends
                break
            status = read_status(self.receive, self.control)
            if status.stopped or status.link_down:
                raise failure(action, status)
            # Speed scaling stretches the profile in time; beyond that (plus a margin) it stalled.
            scaling = max(status.speed_scaling or 1.0, 0.05)
            if self.clock.now() - t_sent > expected_s / scaling + STALL_MARGIN_S:
                _quietly(self.control, "stopL", STOP_DECELERATION_MPS2)
                raise self._fail(f"{action} (no end after {self.clock.now() - t_sent:.1f} s)")
            self.clock.sleep(self._period_s / 2)
        if recorder is not None:
            recorder.sample()

    def _travel(self, target: Pose) -> None:
        """Go to `target`, lifting first when the move is sideways (never drag across keys)."""
        current = self.receive.getActualTCPPose()
        if math.dist(current[:2], target[:2]) <= LATERAL_MOVE_M:
            if math.dist(current[:3], target[:3]) > 1e-5:
                self._move(target, self.travel_velocity_mps, self.travel_acceleration_mps2)
            return
        lift_z = max(current[2], self.reference_pose[2] + self.config.safe_lift_m, target[2])
        lift_z = min(lift_z, self.config.workspace_max_m[2])
        up = [*current[:2], lift_z, *target[3:6]]
        across = [*target[:2], lift_z, *target[3:6]]
        for pose in (up, across, target):  # refuse the whole path before the first move
            self.check_target(pose)
        for pose in (up, across, target):
            self._move(pose, self.travel_velocity_mps, self.travel_acceleration_mps2)

    def move_to_key(self, note: int, distance_m: float) -> None:
        """Hover `distance_m` above the key of `note` (lifting for sideways moves)."""
        self._travel(self.key_pose(note, distance_m))

    def press(self, press: Press, note: int) -> PressRecord:
        """Down by distance + depth at (v_down, a), hold, up at (v_up, a); the TCP trace."""
        for name in ("down_velocity_mps", "up_velocity_mps", "acceleration_mps2"):
            if not getattr(press, name) > 0:
                raise SafetyViolation(f"{name} must be > 0 for a moveL, got {getattr(press, name)}")
        if press.depth_m < 0 or press.distance_m < 0 or press.hold_s < 0:
            raise SafetyViolation(f"distance, depth and hold must be >= 0, got {press}")
        hover = self.key_pose(note, press.distance_m)
        bottom = self.key_pose(note, -press.depth_m)
        self.check_target(hover)
        self.check_target(bottom)
        self._travel(hover)
        recorder = TcpRecorder(self.receive, self.clock)
        t_start_s = self.clock.now()
        try:
            self._move(bottom, press.down_velocity_mps, press.acceleration_mps2, recorder)
            hold_until_s = self.clock.now() + press.hold_s
            while self.clock.now() < hold_until_s:
                recorder.sample()
                self.clock.sleep(min(self._period_s / 2, hold_until_s - self.clock.now()))
            self._move(hover, press.up_velocity_mps, press.acceleration_mps2, recorder)
        except RigError:
            self.make_safe()
            raise
        t_end_s = self.clock.now()
        warnings = []
        if recorder.min_scaling < self.config.max_speed_scaling_warning - 1e-9:
            warnings.append(
                f"speed scaling {recorder.min_scaling:.2f} < 1 stretches every move "
                "(the arm ran slower than commanded)"
            )
        return PressRecord(t_start_s, t_end_s, recorder.trace(hover[2]), tuple(warnings))

    def make_safe(self) -> None:
        """Stop, then retract `safe_lift_m` above the keys if the arm can move. Never raises."""
        _quietly(self.control, "stopL", STOP_DECELERATION_MPS2)
        try:
            status = read_status(self.receive, self.control)
            if status.stopped or status.link_down:
                return  # nothing may move until the link is back or an operator clears the stop
            current = self.receive.getActualTCPPose()
            lift_z = max(current[2], self.reference_pose[2] + self.config.safe_lift_m)
            up = [*current[:2], min(lift_z, self.config.workspace_max_m[2]), *current[3:6]]
            if up[2] - current[2] > 1e-5:
                self.check_target(up)
                self.control.moveL(up, self.travel_velocity_mps, self.travel_acceleration_mps2)
        except Exception:  # make_safe runs on the way out of failures: it must not add one
            pass

    # -- connection --------------------------------------------------------------------------
    def connect(self) -> None:
        """Re-open dropped links (and the control script); ConnectionLost if that fails."""
        for name, link in (("receive", self.receive), ("control", self.control), ("io", self.io)):
            if link is None:
                continue
            try:
                up = bool(link.isConnected())
                if name == "control" and up:
                    up = bool(link.isProgramRunning())
                if not up and not link.reconnect():
                    raise ConnectionLost(f"arm: RTDE {name} did not reconnect to {self.config.host}")
            except RuntimeError as exc:
                raise ConnectionLost(f"arm: RTDE {name} reconnect failed: {exc}") from exc
        status = read_status(self.receive, self.control)
        if status.stopped or status.link_down:
            raise failure("reconnect", status)

    def close(self) -> None:
        """Stop the control script and disconnect every link. Never raises."""
        _quietly(self.control, "stopScript")
        for link in (self.control, self.receive, self.io, self.dashboard):
            _quietly(link, "disconnect")

    def describe(self) -> dict[str, Any]:
        """Host, calibration and controller versions, for run metadata."""
        info: dict[str, Any] = {
            "kind": "ur5",
            "host": self.config.host,
            "frequency_hz": self.config.frequency_hz,
            "reference_pose": self.reference_pose,
            "reference_note": self.geometry.reference_note,
            "calibrated_utc": self.config.calibrated_utc,
            "keyboard_axis": list(self.keyboard_axis),
            "white_pitch_m": self.geometry.white_pitch_m,
        }
        if self.dashboard is not None:
            for key, method in (("polyscope_version", "polyscopeVersion"),
                                ("robot_model", "getRobotModel"),
                                ("serial_number", "getSerialNumber")):
                value = _quietly(self.dashboard, method)
                if value is not None:
                    info[key] = str(value)
        return info


def _quietly(obj: Any, method: str, *args: Any) -> Any:
    """Call obj.method(*args); None if obj is None or the call fails."""
    if obj is None:
        return None
    try:
        return getattr(obj, method)(*args)
    except Exception:  # cleanup and metadata calls must never mask the real error
        return None


def _fmt(pose: Sequence[float]) -> str:
    return "[" + ", ".join(f"{v:.4f}" for v in pose) + "]"
