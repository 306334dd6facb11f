"""The UR5 arm over ur_rtde: calibrated key poses, guarded moveL presses, the TCP trace.

Geometry. The calibrated reference pose has the fingertip resting on the reference key (the B
left of middle C, 1.5 cm from the key's front edge, finger level). Every other key is that pose
shifted along the keyboard axis (a horizontal unit vector in the base frame, from the rig) by the
key-centre distance from `KeyboardGeometry`; the orientation never changes. Heights are base-
frame z (up); the recorded trace is converted to downward displacement from the hover pose, as
everywhere else in pianobot.

Motion. A press is: moveL to hover `distance` above the key, moveL down by distance + depth at
(v_down, a), hold, moveL back up at (v_up, a). A two-segment press (`Press.approach_m`,
`retract_m`) sends up to four moveLs, each from rest to rest: a fast approach that stops above
the key, the spec's move to the bottom, the spec's move up, a fast retract. Every target is
checked against the rig's workspace box and `isPoseWithinSafetyLimits` before the first move
is sent (SafetyViolation, nothing sent). Each moveL is a `GuardedMotion` (ur5_motion): sent only
over live links, waited for with the extended progress call, the TCP sampled once per cycle,
stalls judged on trajectory time so a slow speed slider never reads as one.

Failures are diagnosed from what the controller says (`ur5_status.failure`): stops and pauses
raise SafetyStop (after `make_safe`), a dropped link or an ended control script ConnectionLost.
Taking the arm and recovering it is `ur5_session`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from pianobot.physics.keyboard import KeyboardGeometry
from pianobot.physics.trajectory import Press, check_press
from pianobot.rig.errors import DeviceUnavailable, RigError, SafetyViolation
from pianobot.rig.protocols import Clock, PressRecord
from pianobot.rig.ur5_link import ControllerInfo, quietly
from pianobot.rig.ur5_motion import GuardedMotion, Pose, fmt_pose
from pianobot.rig.ur5_session import Links, close_link, open_links, reconnect
from pianobot.rig.ur5_status import read_status
from pianobot.rig.ur5_trace import TcpRecorder
from pianobot.spec.parameters import PARAMETERS, PRESS_PARAMETERS
from pianobot.spec.rig import UR5Config

DEFAULT_KEYBOARD_AXIS = (1.0, 0.0, 0.0)  # treble towards base +x unless the rig says otherwise
TRAVEL_VELOCITY_MPS = 0.1
TRAVEL_ACCELERATION_MPS2 = 0.5
LATERAL_MOVE_M = 0.0005  # closer than this the arm is already over the key
MISSED_WARNING_FRACTION = 0.1  # warn when the host missed more of the press's cycles than this

# The speeds and acceleration of the moveLs: a UR5 refuses a moveL at 0 (the parameters the
# table says must be > 0, of the arm's motion).
_MOVE_RATES = tuple(n for n in PRESS_PARAMETERS if PARAMETERS[n].exclusive_minimum)


class UR5Arm:
    """The lab arm (implements the `Arm` protocol); ur_rtde objects come in through here.

    Args:
        config: the rig file's `ur5:` section (needs a calibrated `reference_pose`).
        control, receive: `RTDEControlInterface`, `RTDEReceiveInterface` (or fakes).
        io, dashboard: optional `RTDEIOInterface`, `DashboardClient` (reconnected, described).
        clock: the run clock.
        geometry: key positions relative to the reference key.
        keyboard_axis: base-frame horizontal direction from bass to treble.
        controller, rate_hz: what `connect_to` learnt (PolyScope version, RTDE rate in use).
        warnings: what the pre-flight check found (shown before any motion).
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
        controller: ControllerInfo | None = None,
        rate_hz: float | None = None,
        warnings: Sequence[str] = (),
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
        self.links = Links(control, receive, dashboard, controller,
                           rate_hz or config.frequency_hz or (controller.loop_hz if controller
                                                              else 500.0), list(warnings))
        self.io = io
        self.clock = clock
        self.geometry = geometry or KeyboardGeometry(reference_note=config.reference_note)
        self.keyboard_axis = tuple(float(v) for v in axis / norm)
        self.travel_velocity_mps = travel_velocity_mps
        self.travel_acceleration_mps2 = travel_acceleration_mps2
        self.reference_pose: Pose = [float(v) for v in config.reference_pose]
        self.motion = GuardedMotion(self.links, clock)
        self._measured_rate_hz: float | None = None
        # Controller time → run clock offset of the last press's trace (provenance, checks).
        self.last_trace_offset_s: float | None = None

    @property
    def control(self) -> Any:
        return self.links.control

    @property
    def receive(self) -> Any:
        return self.links.receive

    @property
    def dashboard(self) -> Any:
        return self.links.dashboard

    @property
    def rate_hz(self) -> float:
        """The RTDE rate asked of ur_rtde."""
        assert self.links.rate_hz is not None
        return self.links.rate_hz

    @property
    def warnings(self) -> tuple[str, ...]:
        """What the pre-flight check found: to be shown before any motion."""
        return tuple(self.links.warnings)

    @classmethod
    def connect_to(
        cls,
        config: UR5Config,
        *,
        clock: Clock,
        receive_factory: Any = None,
        control_factory: Any = None,
        dashboard_factory: Any = None,
        **options: Any,
    ) -> UR5Arm:
        """Open the dashboard, the receive interface and, after the pre-flight check, the
        control interface (ur_rtde imported lazily). Raises DeviceUnavailable naming the host
        and the reason when the arm cannot be reached or taken. Factories replace the SDK
        classes (tests pass fakes)."""
        if config.reference_pose is None:  # fail before taking control of the arm
            raise DeviceUnavailable(
                "the UR5 has no calibrated reference pose: run `pianobot rig calibrate RIGFILE`"
            )
        links = open_links(config, receive_factory=receive_factory,
                           control_factory=control_factory, dashboard_factory=dashboard_factory)
        return cls(config, control=links.control, receive=links.receive,
                   dashboard=links.dashboard, clock=clock, controller=links.controller,
                   rate_hz=links.rate_hz, warnings=links.warnings, **options)

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
                    f"(pose {fmt_pose(pose)})"
                )
        self.motion.check_reach(pose)

    def _move(self, target: Pose, speed_mps: float, acceleration_mps2: float,
              recorder: TcpRecorder | None = None) -> None:
        """Check the target, then one guarded moveL to it."""
        self.check_target(target)
        self.motion.move(target, speed_mps, acceleration_mps2, recorder)

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
        """Down, hold, up — as one moveL each way, or as a two-segment press (fast approach to
        `approach_m` below the hover, the spec's move to the bottom, hold, the spec's move up to
        `retract_m` below the hover, a fast retract) — with the TCP trace of all of it."""
        try:
            check_press(press)
        except ValueError as exc:
            raise SafetyViolation(str(exc)) from exc
        for name in _MOVE_RATES:
            if not getattr(press, name) > 0:
                raise SafetyViolation(f"{name} must be > 0 for a moveL, got {getattr(press, name)}")
        hover = self.key_pose(note, press.distance_m)
        bottom = self.key_pose(note, -press.depth_m)
        moves = self._press_moves(press, note, bottom)
        for target, _, _ in moves:  # refuse the whole press before the first move
            self.check_target(target)
        self._travel(hover)
        recorder = TcpRecorder(self.receive, self.clock)
        self.motion.min_scaling = math.inf
        t_start_s = self.clock.now()
        try:
            for target, speed, acceleration in moves:
                self._move(target, speed, acceleration, recorder)
                if target is bottom:
                    self._hold(press.hold_s, recorder)
        except RigError:
            self.make_safe()
            raise
        t_end_s = self.clock.now()
        if recorder.period_s is not None:
            self._measured_rate_hz = 1.0 / recorder.period_s
        self.last_trace_offset_s = recorder.offset_s
        return PressRecord(t_start_s, t_end_s, recorder.trace(hover[2]),
                           self._press_warnings(recorder))

    def _press_moves(self, press: Press, note: int,
                     bottom: Pose) -> list[tuple[Pose, float, float]]:
        """(target, speed, acceleration) of each moveL of the press, in order."""
        fast = (press.travel_velocity_mps, press.travel_acceleration_mps2)
        spec_down = (press.down_velocity_mps, press.acceleration_mps2)
        spec_up = (press.up_velocity_mps, press.acceleration_mps2)
        moves: list[tuple[Pose, float, float]] = []
        if press.approach_m > 0.0:  # stops above the key (check_press)
            moves.append((self.key_pose(note, press.distance_m - press.approach_m), *fast))
        moves.append((bottom, *spec_down))
        moves.append((self.key_pose(note, press.distance_m - press.retract_m), *spec_up))
        if press.retract_m > 0.0:  # starts at or above the key surface (check_press)
            moves.append((self.key_pose(note, press.distance_m), *fast))
        return moves

    def _hold(self, hold_s: float, recorder: TcpRecorder) -> None:
        hold_until_s = self.clock.now() + hold_s
        while self.clock.now() < hold_until_s:
            recorder.sample()
            self.clock.sleep(min(0.5 / self.rate_hz, hold_until_s - self.clock.now()))

    def _press_warnings(self, recorder: TcpRecorder) -> tuple[str, ...]:
        warnings = []
        if self.motion.min_scaling < 1.0 - 1e-6:
            warnings.append(
                f"speed scaling fell to {self.motion.min_scaling:.2f} during the press (speed slider "
                "or trajectory limiter): the arm ran slower than commanded"
            )
        samples = len(recorder.ctrl_s)
        missed = recorder.missed_cycles
        if samples and missed > MISSED_WARNING_FRACTION * (samples + missed):
            warnings.append(f"the arm trace misses {missed} of {samples + missed} controller "
                            "cycles (the host was too busy to read them)")
        return tuple(warnings)

    def make_safe(self) -> None:
        """Stop, then retract `safe_lift_m` above the keys if the arm can move. Never raises."""
        self.motion.stop()
        try:
            status = read_status(self.receive, self.control)
            if status.stopped or status.link_down or status.paused or status.script_stopped:
                return  # nothing may move until the link is back or an operator acts
            current = self.receive.getActualTCPPose()
            lift_z = max(current[2], self.reference_pose[2] + self.config.safe_lift_m)
            up = [*current[:2], min(lift_z, self.config.workspace_max_m[2]), *current[3:6]]
            if up[2] - current[2] > 1e-5:  # guarded: a synchronous moveL could wait 300 s
                self._move(up, self.travel_velocity_mps, self.travel_acceleration_mps2)
        except Exception:  # make_safe runs on the way out of failures: it must not add one
            pass

    # -- connection --------------------------------------------------------------------------
    def connect(self) -> None:
        """Re-open dropped links, re-upload an ended control script; ConnectionLost if a link
        stays down, SafetyStop if an operator must act first."""
        reconnect(self.links, self.io, self.config.host)

    def close(self) -> None:
        """Stop the control script and disconnect every link. Never raises."""
        if self.motion.links_up() and quietly(self.control, "isProgramRunning"):
            quietly(self.control, "stopScript")
        for link in (self.control, self.receive, self.io):
            close_link(link)
        quietly(self.dashboard, "disconnect")

    def describe(self) -> dict[str, Any]:
        """Host, controller, RTDE rate, calibration, for run metadata."""
        controller = self.links.controller
        info: dict[str, Any] = {
            "kind": "ur5",
            "host": self.config.host,
            "rtde_rate_hz": self.rate_hz,
            "rtde_rate_source": "rig file" if self.config.frequency_hz is not None
            else "controller version",
            "measured_rate_hz": self._measured_rate_hz,
            "controller": None if controller is None else controller.to_dict(),
            "warnings": list(self.warnings),
            "reference_pose": self.reference_pose,
            "reference_note": self.geometry.reference_note,
            "calibrated_utc": self.config.calibrated_utc,
            "keyboard_axis": list(self.keyboard_axis),
            "white_pitch_m": self.geometry.white_pitch_m,
        }
        if self.dashboard is not None:
            for key, method in (("robot_model", "getRobotModel"),
                                ("serial_number", "getSerialNumber")):
                value = quietly(self.dashboard, method)
                if value is not None:
                    info[key] = str(value)
        return info
