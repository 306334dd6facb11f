"""UR5Arm against fakes of the ur_rtde objects (same method names, same failure habits)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from fake_rtde import (
    CONTROLLER_EPOCH_S,
    CONTROLLER_PERIOD_S,
    FakeClock,
    FakeControl,
    FakeController,
    FakeReceive,
    sdk_factories,
)

from pianobot.physics.keyboard import KeyboardGeometry
from pianobot.physics.trajectory import Press, move_profile
from pianobot.rig.errors import (
    ConnectionLost,
    DeviceUnavailable,
    RigError,
    SafetyStop,
    SafetyViolation,
)
from pianobot.rig.protocols import Arm
from pianobot.rig.ur5 import UR5Arm
from pianobot.rig.ur5_status import ArmStatus, failure
from pianobot.spec.rig import UR5Config

HOST = "192.0.2.10"
REFERENCE_POSE = (0.45, -0.10, 0.10, 0.0, math.pi, 0.0)
PRESS = Press(
    distance_m=0.02, depth_m=0.01, down_velocity_mps=0.05, up_velocity_mps=0.1,
    acceleration_mps2=0.5, hold_s=0.1,
)


def make_config(**overrides: object) -> UR5Config:
    fields: dict[str, object] = {
        "host": "192.0.2.10",
        "workspace_min_m": (0.2, -0.5, 0.05),
        "workspace_max_m": (0.7, 0.5, 0.35),
        "reference_pose": REFERENCE_POSE,
        "calibrated_utc": "2026-01-01T00:00:00Z",
    }
    fields.update(overrides)
    return UR5Config.model_validate(fields)


@pytest.fixture()
def robot() -> FakeController:
    return FakeController(clock=FakeClock(10.0))


def make_arm(robot: FakeController, **overrides: object) -> UR5Arm:
    return UR5Arm(
        make_config(**overrides),
        control=FakeControl(robot, HOST),
        receive=FakeReceive(robot, HOST),
        clock=robot.clock,
    )


def moves(robot: FakeController) -> list[list[float]]:
    return [args[0] for args in robot.calls_to("moveL")]


def test_satisfies_the_arm_protocol(robot: FakeController) -> None:
    assert isinstance(make_arm(robot), Arm)


def test_key_poses_follow_the_keyboard_geometry(robot: FakeController) -> None:
    arm = make_arm(robot)
    assert arm.key_pose(59) == pytest.approx(list(REFERENCE_POSE))
    c4 = arm.key_pose(60, 0.02)
    assert c4[0] - REFERENCE_POSE[0] == pytest.approx(0.0235)  # one white key to the right
    assert c4[2] == pytest.approx(REFERENCE_POSE[2] + 0.02)
    c_sharp = arm.key_pose(61)
    assert c_sharp[0] - REFERENCE_POSE[0] == pytest.approx(1.4 * 0.0235)  # C# leans left
    assert c_sharp[3:] == pytest.approx(list(REFERENCE_POSE[3:]))


def test_keyboard_axis_and_offsets_come_from_the_rig(robot: FakeController) -> None:
    arm = UR5Arm(
        make_config(),
        control=FakeControl(robot, HOST),
        receive=FakeReceive(robot, HOST),
        clock=robot.clock,
        geometry=KeyboardGeometry(0.0235, 59, ((57, 0.001),)),
        keyboard_axis=(0.0, -2.0, 0.0),
    )
    a3 = arm.key_pose(57)
    assert a3[0] == pytest.approx(REFERENCE_POSE[0])
    assert a3[1] - REFERENCE_POSE[1] == pytest.approx(-(-0.0235 + 0.001))  # A3 is one white key left


def test_press_records_the_tcp_trace_with_controller_timestamps(robot: FakeController) -> None:
    arm = make_arm(robot)
    arm.move_to_key(57, PRESS.distance_m)
    n_travel = len(moves(robot))
    record = arm.press(PRESS, 57)

    down, up = moves(robot)[n_travel:]
    hover = arm.key_pose(57, PRESS.distance_m)
    assert down[2] == pytest.approx(hover[2] - PRESS.distance_m - PRESS.depth_m)
    assert up == pytest.approx(hover)
    assert [args[1:] for args in robot.calls_to("moveL")[n_travel:]] == [
        (PRESS.down_velocity_mps, PRESS.acceleration_mps2, True),
        (PRESS.up_velocity_mps, PRESS.acceleration_mps2, True),
    ]

    trace = record.arm
    assert trace is not None and trace.x0_m is not None and trace.source == "arm"
    # One sample per controller tick (500 Hz), mapped onto the run clock.
    steps = np.diff(trace.t_s)
    assert np.allclose(steps, CONTROLLER_PERIOD_S, atol=1e-9)
    assert abs(trace.t_s[0] - record.t_start_s) < CONTROLLER_PERIOD_S
    assert record.t_start_s < record.t_end_s
    assert trace.t_s[-1] <= record.t_end_s + 1e-9
    # Downward displacement from the hover pose: 0 → distance + depth → 0.
    travel_m = PRESS.distance_m + PRESS.depth_m
    assert trace.x0_m[0] == pytest.approx(0.0, abs=1e-4)
    assert trace.x0_m.max() == pytest.approx(travel_m, abs=1e-9)
    assert trace.x0_m[-1] == pytest.approx(0.0, abs=1e-9)
    # The down stroke follows the moveL trapezoid.
    profile = move_profile(travel_m, PRESS.down_velocity_mps, PRESS.acceleration_mps2)
    t_rel = trace.t_s - trace.t_s[0]
    going_down = t_rel <= profile.duration_s
    expected, _ = profile.sample(t_rel[going_down])
    assert np.max(np.abs(trace.x0_m[going_down] - expected)) < 2e-4
    at_bottom = np.isclose(trace.x0_m, travel_m, atol=1e-9)
    assert np.ptp(trace.t_s[at_bottom]) >= PRESS.hold_s - 2 * CONTROLLER_PERIOD_S
    assert record.warnings == ()


def test_trace_clock_mapping_uses_the_controller_time(robot: FakeController) -> None:
    arm = make_arm(robot)
    record = arm.press(PRESS, 59)
    assert record.arm is not None
    # The fake controller's clock is the run clock shifted by its epoch, in 2 ms ticks: the
    # mapped times are those ticks shifted back (a read can lag its tick by < one period).
    ticks = record.arm.t_s + CONTROLLER_EPOCH_S
    assert np.allclose(ticks / CONTROLLER_PERIOD_S, np.round(ticks / CONTROLLER_PERIOD_S),
                       atol=0.51)


def test_speed_slider_below_one_stretches_and_warns(robot: FakeController) -> None:
    robot.speed_slider = 0.5
    arm = make_arm(robot)
    arm.move_to_key(59, PRESS.distance_m)
    record = arm.press(PRESS, 59)
    assert len(record.warnings) == 1 and "speed scaling fell to 0.50" in record.warnings[0]
    travel_m = PRESS.distance_m + PRESS.depth_m
    nominal_s = (
        move_profile(travel_m, PRESS.down_velocity_mps, PRESS.acceleration_mps2).duration_s
        + PRESS.hold_s
        + move_profile(travel_m, PRESS.up_velocity_mps, PRESS.acceleration_mps2).duration_s
    )
    assert record.t_end_s - record.t_start_s > 1.8 * nominal_s - PRESS.hold_s


def test_target_outside_the_workspace_is_refused_before_sending(robot: FakeController) -> None:
    arm = make_arm(robot)
    with pytest.raises(SafetyViolation, match="outside the workspace"):
        arm.move_to_key(108, 0.02)  # C8: 1.2 m to the right of the reference key
    too_deep = Press(0.02, 0.06, 0.05, 0.1, 0.5)  # bottom at z = 0.04 < 0.05
    with pytest.raises(SafetyViolation, match="z = 0.0400 m is outside"):
        arm.press(too_deep, 59)
    assert moves(robot) == []


def test_pose_outside_the_robot_safety_limits_is_refused(robot: FakeController) -> None:
    robot.reach_m = 0.3
    arm = make_arm(robot)
    with pytest.raises(SafetyViolation, match="safety limits"):
        arm.move_to_key(59, 0.02)
    assert robot.calls_to("isPoseWithinSafetyLimits")
    assert moves(robot) == []


def test_bad_press_parameters_are_refused(robot: FakeController) -> None:
    arm = make_arm(robot)
    with pytest.raises(SafetyViolation, match="down_velocity_mps must be > 0"):
        arm.press(Press(0.02, 0.01, 0.0, 0.1, 0.5), 59)
    assert moves(robot) == []


def test_protective_stop_mid_press_aborts_safely_and_is_not_retried(
    robot: FakeController,
) -> None:
    arm = make_arm(robot)
    arm.move_to_key(59, PRESS.distance_m)
    n_before = len(moves(robot))
    robot.fail_on_move = robot._moves_started + 1  # the down stroke
    robot.fail_what = "protective_stop"
    with pytest.raises(SafetyStop, match="protective stopped"):
        arm.press(PRESS, 59)
    # Safe abort: the motion was stopped and nothing else was sent to the stopped robot.
    assert robot.calls_to("stopL")
    assert len(moves(robot)) == n_before + 1
    # A reconnect does not clear a stop: the runner cannot resume without an operator.
    with pytest.raises(SafetyStop):
        arm.connect()
    assert len(moves(robot)) == n_before + 1


def test_emergency_stop_is_a_safety_stop(robot: FakeController) -> None:
    arm = make_arm(robot)
    arm.move_to_key(59, PRESS.distance_m)
    robot.fail_on_move = robot._moves_started + 2  # the up stroke
    robot.fail_what = "emergency_stop"
    with pytest.raises(SafetyStop, match="emergency stopped"):
        arm.press(PRESS, 59)


def test_connection_drop_mid_press_reconnects_and_retries(robot: FakeController) -> None:
    arm = make_arm(robot)
    arm.move_to_key(59, PRESS.distance_m)
    robot.fail_on_move = robot._moves_started + 1
    robot.fail_what = "drop"
    attempts = 0
    record = None
    for _ in range(3):  # the runner's policy: reconnect on ConnectionLost, retry the trial
        attempts += 1
        try:
            arm.move_to_key(59, PRESS.distance_m)
            record = arm.press(PRESS, 59)
            break
        except ConnectionLost:
            arm.connect()
    assert attempts == 2 and record is not None and record.arm is not None
    assert robot.calls_to("reconnect")  # both links were re-opened
    assert record.arm.x0_m is not None
    assert record.arm.x0_m.max() == pytest.approx(PRESS.distance_m + PRESS.depth_m)


def test_reconnect_that_fails_raises_connection_lost(robot: FakeController) -> None:
    arm = make_arm(robot)
    robot.connected = False
    robot.reconnect_works = False
    with pytest.raises(ConnectionLost, match="did not reconnect"):
        arm.connect()


def test_make_safe_retracts_and_never_raises(robot: FakeController) -> None:
    arm = make_arm(robot)
    arm.move_to_key(59, 0.0)
    arm.make_safe()
    assert robot.pose[2] == pytest.approx(REFERENCE_POSE[2] + 0.05)

    class Broken:
        def __getattr__(self, name: str) -> object:
            raise RuntimeError("link gone")

    broken = UR5Arm(make_config(), control=Broken(), receive=Broken(), clock=robot.clock)
    broken.make_safe()
    broken.close()


def test_moves_between_keys_lift_first(robot: FakeController) -> None:
    arm = make_arm(robot)
    arm.move_to_key(59, 0.02)
    n = len(moves(robot))
    arm.move_to_key(64, 0.02)
    up, across, down = moves(robot)[n:]
    lift_z = REFERENCE_POSE[2] + 0.05
    assert up[2] == pytest.approx(lift_z) and across[2] == pytest.approx(lift_z)
    assert down == pytest.approx(arm.key_pose(64, 0.02))


def test_uncalibrated_arm_is_unavailable(robot: FakeController) -> None:
    with pytest.raises(DeviceUnavailable, match="rig calibrate"):
        make_arm(robot, reference_pose=None)


def connect(robot: FakeController, **config: object) -> UR5Arm:
    fakes = sdk_factories(robot)
    return UR5Arm.connect_to(make_config(**config), clock=robot.clock,
                             receive_factory=fakes["receive"], control_factory=fakes["control"],
                             dashboard_factory=fakes["dashboard"])


def test_connect_to_maps_a_refused_connection(robot: FakeController) -> None:
    robot.listening = False
    with pytest.raises(DeviceUnavailable, match=r"192\.0\.2\.10:29999: connect failed"):
        connect(robot)
    robot.listening = True
    fakes = sdk_factories(robot)

    def refusing_receive(*args: object) -> FakeReceive:
        robot.listening = False
        return fakes["receive"](*args)

    with pytest.raises(DeviceUnavailable, match=r"192\.0\.2\.10:30004: ur_rtde could not connect"):
        UR5Arm.connect_to(make_config(), clock=robot.clock, receive_factory=refusing_receive,
                          dashboard_factory=fakes["dashboard"])


@pytest.mark.parametrize(("polyscope", "rate_hz"), [
    ("URSoftware 5.11.1.108318 (Aug 24 2021)", 500.0),
    ("URSoftware 3.15.7.106331 (Feb 02 2022)", 125.0),
])
def test_connect_to_picks_the_rate_from_the_controller(
    robot: FakeController, polyscope: str, rate_hz: float,
) -> None:
    robot.polyscope = polyscope
    arm = connect(robot)
    assert ("control", "__init__", (HOST, rate_hz)) in robot.calls
    assert ("receive", "__init__", (HOST, rate_hz)) in robot.calls
    assert arm.rate_hz == rate_hz and arm.describe()["rtde_rate_source"] == "controller version"
    assert arm.press(PRESS, 59).arm is not None


def test_a_rate_above_the_controller_loop_is_lowered_with_a_warning(robot: FakeController) -> None:
    robot.polyscope = "URSoftware 3.15.7.106331 (Feb 02 2022)"
    arm = connect(robot, frequency_hz=500.0)
    assert arm.rate_hz == 125.0
    assert any("125 Hz" in w for w in arm.warnings)
    robot.polyscope = "URSoftware 5.11.1.108318 (Aug 24 2021)"
    assert connect(robot, frequency_hz=250.0).rate_hz == 250.0


def test_connect_to_an_unreachable_host_fails_fast() -> None:
    config = make_config(host="127.0.0.1", connect_timeout_s=0.5)
    with pytest.raises(DeviceUnavailable, match=r"127\.0\.0\.1:29999"):
        UR5Arm.connect_to(config, clock=FakeClock())


def status(**changes: object) -> ArmStatus:
    fields: dict[str, object] = {
        "receive_connected": True, "control_connected": True, "program_running": True,
        "protective_stopped": False, "emergency_stopped": False, "safety_status_bits": 1,
        "robot_mode": 7, "safety_mode": 1, "runtime_state": 2, "speed_slider": 1.0,
        "speed_scaling": 1.0, "speed_scaling_combined": 1.0,
    }
    fields.update(changes)
    return ArmStatus(**fields)  # type: ignore[arg-type]


def test_unknown_failures_are_not_mislabelled() -> None:
    assert type(failure("moveL", status())) is RigError
    assert isinstance(failure("moveL", status(robot_mode=3)), SafetyStop)
    script_dead = status(program_running=False, runtime_state=1)
    assert isinstance(failure("moveL", script_dead), ConnectionLost)
    paused = status(program_running=False, runtime_state=4, speed_scaling_combined=0.0)
    assert isinstance(failure("moveL", paused), SafetyStop)
    assert "paused" in str(failure("moveL", paused))
    assert isinstance(failure("moveL", status(speed_slider=0.0)), SafetyStop)


def test_a_dead_control_script_is_a_connection_loss(robot: FakeController) -> None:
    arm = make_arm(robot)
    robot.program_running = False  # moveL answers False, as ur_rtde does
    with pytest.raises(ConnectionLost, match="control script not running"):
        arm.move_to_key(59, 0.02)
    arm.connect()  # the links are up: only the script is re-uploaded
    assert robot.calls_to("reuploadScript") and not robot.calls_to("reconnect")
    assert robot.program_running
    arm.move_to_key(59, 0.02)
    assert robot.pose == pytest.approx(arm.key_pose(59, 0.02))


def test_a_two_segment_press_is_four_moves_each_checked_before_the_first(
    robot: FakeController,
) -> None:
    arm = make_arm(robot)
    two = Press(0.05, 0.02, 0.03, 0.05, 1.0, 0.1, approach_m=0.03, retract_m=0.04,
                travel_velocity_mps=0.25, travel_acceleration_mps2=1.5)
    arm.move_to_key(59, two.distance_m)
    n = len(moves(robot))
    record = arm.press(two, 59)
    sent = robot.calls_to("moveL")[n:]
    hover_z = REFERENCE_POSE[2] + two.distance_m
    assert [round(args[0][2] - hover_z, 9) for args in sent] == [-0.03, -0.07, -0.04, 0.0]
    assert [args[1:3] for args in sent] == [(0.25, 1.5), (0.03, 1.0), (0.05, 1.0), (0.25, 1.5)]
    assert record.arm is not None and record.arm.x0_m is not None
    assert record.arm.x0_m.max() == pytest.approx(0.07)
    # Checked before sending: a fast approach into the key is refused, nothing moves.
    n = len(moves(robot))
    with pytest.raises(SafetyViolation, match="stop above the key"):
        arm.press(Press(0.05, 0.02, 0.03, 0.05, 1.0, approach_m=0.06), 59)
    robot.reach_m = 0.1  # every target outside the robot's reach: refused before the first
    with pytest.raises(SafetyViolation, match="safety limits"):
        arm.press(two, 59)
    assert len(moves(robot)) == n


class RacingReceive(FakeReceive):
    """A receive interface where a new package lands between the timestamp and the pose read
    of every other sample (ur_rtde's receive thread runs beside the caller)."""

    def __init__(self, controller: FakeController, hostname: str) -> None:
        super().__init__(controller, hostname)
        self.truth: dict[float, float] = {}
        self._reads = 0

    def getTimestamp(self) -> float:  # noqa: N802
        ts = super().getTimestamp()
        self.truth[round(ts, 9)] = self.c.pose[2]
        return ts

    def getActualTCPPose(self) -> list[float]:  # noqa: N802
        self._reads += 1
        if self._reads % 2 == 0:
            self.c.clock.sleep(CONTROLLER_PERIOD_S)  # the next package arrives now
        pose = super().getActualTCPPose()
        self.truth[round(self.c.controller_time_s(), 9)] = pose[2]
        return pose


def test_a_package_arriving_mid_sample_never_pairs_a_pose_with_the_wrong_time(
    robot: FakeController,
) -> None:
    receive = RacingReceive(robot, HOST)
    arm = UR5Arm(make_config(), control=FakeControl(robot, HOST), receive=receive,
                 clock=robot.clock)
    arm.move_to_key(59, PRESS.distance_m)
    record = arm.press(PRESS, 59)
    assert record.arm is not None and record.arm.x0_m is not None and arm.last_trace_offset_s
    ctrl = np.round(record.arm.t_s - arm.last_trace_offset_s, 9)
    hover_z = arm.key_pose(59, PRESS.distance_m)[2]
    mismatched = [t for t, x0 in zip(ctrl, record.arm.x0_m, strict=True)
                  if abs(hover_z - x0 - receive.truth[t]) > 1e-12]
    assert len(ctrl) > 100 and not mismatched
