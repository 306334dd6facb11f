"""Fakes of the ur_rtde interfaces with the same method names and failure habits.

One `FakeController` is the robot; `FakeControl`, `FakeReceive`, `FakeIO` and `FakeDashboard`
are the four ur_rtde objects talking to it. Like the real ones:

- construction raises RuntimeError when nothing listens (`controller.listening = False`);
- commands return False instead of raising (protective stop, dead control script, drop);
- an asynchronous `moveL` returns at once, `getAsyncOperationProgress()` is >= 0 while it runs
  and toggles between -1 and -2 when moves finish;
- the controller time (`getTimestamp`) advances in 2 ms ticks (500 Hz), on its own origin.

Time comes from a `FakeClock` shared with the code under test, so runs are deterministic and
fast. Every call is recorded in `controller.calls` as (interface, method, args).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from pianobot.physics.trajectory import move_profile

CONTROLLER_PERIOD_S = 0.002
CONTROLLER_EPOCH_S = 4711.25  # controller uptime when the fake clock reads 0
PROTECTIVE_STOP_BIT = 1 << 2
EMERGENCY_STOP_BIT = 1 << 7
NORMAL_MODE_BIT = 1 << 0
ROBOT_MODE_RUNNING = 7
SAFETY_MODE_NORMAL = 1
SAFETY_MODE_PROTECTIVE_STOP = 3
SAFETY_MODE_ROBOT_EMERGENCY_STOP = 7


class FakeClock:
    """A virtual run clock: sleep() advances time instantly."""

    def __init__(self, t_s: float = 0.0) -> None:
        self.t_s = t_s

    def now(self) -> float:
        return self.t_s

    def sleep(self, seconds: float) -> None:
        self.t_s += max(seconds, 0.0)


@dataclass
class _Move:
    start: list[float]
    target: list[float]
    t0_s: float
    duration_s: float
    profile: Any


@dataclass
class FakeController:
    """The robot and its control box, shared by the four fake interfaces."""

    clock: FakeClock
    pose: list[float] = field(default_factory=lambda: [0.40, -0.10, 0.20, 0.0, math.pi, 0.0])
    listening: bool = True
    connected: bool = True
    program_running: bool = True
    protective_stopped: bool = False
    emergency_stopped: bool = False
    speed_scaling: float = 1.0
    robot_mode: int = ROBOT_MODE_RUNNING
    reach_m: float = 0.85  # isPoseWithinSafetyLimits: inside this sphere around the base
    reconnect_works: bool = True
    # Failure injection: on the n-th moveL (1-based), `what` happens `after_s` into the move.
    fail_on_move: int | None = None
    fail_what: str = "protective_stop"  # "protective_stop" | "emergency_stop" | "drop"
    fail_after_s: float = 0.05
    analog_out: list[float] = field(default_factory=lambda: [0.0, 0.0])  # voltage ratios
    regulator_tau_s: float = 0.5  # the vacuum regulator follows the analog output like this
    regulator_gain: float = 1.0  # monitor volts per commanded volt (1 = perfect regulator)
    regulator_output_channel: int = 1  # the analog output that drives the regulator
    regulator_input_channel: int = 0  # the analog input its monitor output is wired to
    calls: list[tuple[str, str, tuple[Any, ...]]] = field(default_factory=list)
    on_tick: Callable[[FakeController], None] | None = None  # e.g. a piano watching the TCP
    _move: _Move | None = None
    _moves_started: int = 0
    _progress: int = -1
    _last_finished: int = -1
    _updated_at_s: float = -1.0
    _regulator: tuple[float, float, float] = (0.0, 0.0, 0.0)  # (volts at t, target volts, t)

    # -- time and motion -------------------------------------------------------------------
    def controller_time_s(self) -> float:
        ticks = math.floor((self.clock.now() + CONTROLLER_EPOCH_S) / CONTROLLER_PERIOD_S + 1e-9)
        return ticks * CONTROLLER_PERIOD_S

    def update(self) -> None:
        """Advance the motion to the current controller tick (once per tick, like the robot)."""
        move = self._move
        if move is None:
            return
        tick_s = self.controller_time_s()
        if tick_s == self._updated_at_s:
            return
        self._updated_at_s = tick_s
        t = tick_s - CONTROLLER_EPOCH_S - move.t0_s
        if (
            self.fail_on_move == self._moves_started
            and t >= self.fail_after_s
            and not self._failed()
        ):
            self._inject_failure(move, self.fail_after_s)
            return
        if t >= move.duration_s:
            self.pose = list(move.target)
            self._finish_move()
        else:
            self.pose = self._pose_along(move, max(t, 0.0))
        if self.on_tick is not None:
            self.on_tick(self)

    def _pose_along(self, move: _Move, t_s: float) -> list[float]:
        travelled = _travelled_m(move.profile, t_s * self.speed_scaling)
        length = move.profile.distance_m
        fraction = travelled / length if length > 0 else 1.0
        return [s + fraction * (e - s) for s, e in zip(move.start, move.target, strict=True)]

    def _failed(self) -> bool:
        return self.protective_stopped or self.emergency_stopped or not self.connected

    def _inject_failure(self, move: _Move, at_s: float) -> None:
        self.pose = self._pose_along(move, at_s)
        if self.fail_what == "protective_stop":
            self.protective_stopped = True
            self.program_running = False
        elif self.fail_what == "emergency_stop":
            self.emergency_stopped = True
            self.program_running = False
        else:
            self.connected = False
        self._finish_move()
        self.fail_on_move = None

    def _finish_move(self) -> None:
        # Like the control script: each finished move toggles the register between -1 and -2.
        self._move = None
        self._last_finished = -2 if self._last_finished == -1 else -1
        self._progress = self._last_finished

    def start_move(self, target: list[float], speed: float, acceleration: float) -> bool:
        self.update()
        if self._failed() or not self.program_running:
            return False
        length = math.dist(self.pose[:3], target[:3])
        # Speed scaling slows the whole profile in time: v·s and a·s².
        profile = move_profile(max(length, 1e-12), speed, acceleration)
        duration = profile.duration_s / self.speed_scaling
        self._moves_started += 1
        self._updated_at_s = -1.0
        self._move = _Move(list(self.pose), list(target), self.clock.now(), duration, profile)
        self._progress = 0
        return True

    def progress(self) -> int:
        self.update()
        return self._progress

    def stop(self) -> None:
        self.update()
        if self._move is not None:
            self._finish_move()

    # -- analog I/O with a first-order regulator -------------------------------------------
    def set_analog(self, channel: int, ratio: float) -> None:
        self.analog_out[channel] = ratio
        if channel == self.regulator_output_channel:
            now = self.clock.now()
            volts = self._regulator_volts()
            self._regulator = (volts, ratio * 10.0 * self.regulator_gain, now)

    def _regulator_volts(self) -> float:
        value, target, t0 = self._regulator
        dt = self.clock.now() - t0
        return target + (value - target) * math.exp(-dt / self.regulator_tau_s)

    def analog_in(self, channel: int) -> float:
        """Volts on an analog input: the regulator's monitor output where it is wired."""
        return self._regulator_volts() if channel == self.regulator_input_channel else 0.0

    def safety_bits(self) -> int:
        bits = 0
        if self.protective_stopped:
            bits |= PROTECTIVE_STOP_BIT
        if self.emergency_stopped:
            bits |= EMERGENCY_STOP_BIT
        return bits or NORMAL_MODE_BIT

    def record(self, interface: str, method: str, *args: Any) -> None:
        self.calls.append((interface, method, args))

    def calls_to(self, method: str) -> list[tuple[Any, ...]]:
        return [args for _, name, args in self.calls if name == method]


def _travelled_m(profile: Any, t_s: float) -> float:
    """Distance covered `t_s` into a trapezoid/triangle move (scalar, fast)."""
    a, ta, vp, total = (profile.acceleration_mps2, profile.t_accel_s,
                        profile.peak_velocity_mps, profile.duration_s)
    if t_s <= 0.0:
        return 0.0
    if t_s >= total:
        return float(profile.distance_m)
    if t_s < ta:
        return 0.5 * a * t_s * t_s
    if t_s <= total - ta:
        return 0.5 * vp * ta + vp * (t_s - ta)
    left = total - t_s
    return float(profile.distance_m) - 0.5 * a * left * left


def _refuse_if_nothing_listens(controller: FakeController, host: str) -> None:
    if not controller.listening:
        raise RuntimeError(f"Error: Could not connect to: {host} at 30004, verify the IP")


class FakeControl:
    """rtde_control.RTDEControlInterface."""

    def __init__(self, controller: FakeController, host: str = "192.0.2.10",
                 frequency: float = 500.0) -> None:
        _refuse_if_nothing_listens(controller, host)
        self.c = controller
        self.c.record("control", "__init__", host, frequency)

    def moveL(self, pose: list[float], speed: float = 0.25, acceleration: float = 1.2,  # noqa: N802
              asynchronous: bool = False) -> bool:
        self.c.record("control", "moveL", list(pose), speed, acceleration, asynchronous)
        if not self.c.start_move(list(pose), speed, acceleration):
            return False
        if asynchronous:
            return True
        while self.c.progress() >= 0:  # blocking: let the clock run until the move ends
            self.c.clock.sleep(CONTROLLER_PERIOD_S)
        return not self.c._failed()

    def stopL(self, a: float = 10.0, asynchronous: bool = False) -> None:  # noqa: N802
        self.c.record("control", "stopL", a, asynchronous)
        self.c.stop()

    def getAsyncOperationProgress(self) -> int:  # noqa: N802
        return self.c.progress()

    def isPoseWithinSafetyLimits(self, pose: list[float]) -> bool:  # noqa: N802
        self.c.record("control", "isPoseWithinSafetyLimits", list(pose))
        return math.hypot(*pose[:3]) <= self.c.reach_m

    def isConnected(self) -> bool:  # noqa: N802
        return self.c.connected

    def isProgramRunning(self) -> bool:  # noqa: N802
        self.c.update()
        return self.c.connected and self.c.program_running

    def reconnect(self) -> bool:
        self.c.record("control", "reconnect")
        if not (self.c.listening and self.c.reconnect_works):
            return False
        self.c.connected = True
        if not (self.c.protective_stopped or self.c.emergency_stopped):
            self.c.program_running = True  # reconnecting re-uploads the control script
        return True

    def teachMode(self) -> bool:  # noqa: N802
        self.c.record("control", "teachMode")
        return self.c.connected and self.c.program_running

    def endTeachMode(self) -> bool:  # noqa: N802
        self.c.record("control", "endTeachMode")
        return self.c.connected

    def stopScript(self) -> None:  # noqa: N802
        self.c.record("control", "stopScript")
        self.c.program_running = False

    def disconnect(self) -> None:
        self.c.record("control", "disconnect")


class FakeReceive:
    """rtde_receive.RTDEReceiveInterface."""

    def __init__(self, controller: FakeController, host: str = "192.0.2.10",
                 frequency: float = 500.0) -> None:
        _refuse_if_nothing_listens(controller, host)
        self.c = controller
        self.c.record("receive", "__init__", host, frequency)

    def getActualTCPPose(self) -> list[float]:  # noqa: N802
        self.c.update()
        return list(self.c.pose)

    def getTimestamp(self) -> float:  # noqa: N802
        self.c.update()
        return self.c.controller_time_s()

    def getSafetyStatusBits(self) -> int:  # noqa: N802
        return self.c.safety_bits()

    def getRobotMode(self) -> int:  # noqa: N802
        return self.c.robot_mode

    def getSafetyMode(self) -> int:  # noqa: N802
        if self.c.emergency_stopped:
            return SAFETY_MODE_ROBOT_EMERGENCY_STOP
        return SAFETY_MODE_PROTECTIVE_STOP if self.c.protective_stopped else SAFETY_MODE_NORMAL

    def getSpeedScaling(self) -> float:  # noqa: N802
        return self.c.speed_scaling

    def isProtectiveStopped(self) -> bool:  # noqa: N802
        self.c.update()
        return self.c.protective_stopped

    def isEmergencyStopped(self) -> bool:  # noqa: N802
        self.c.update()
        return self.c.emergency_stopped

    def getStandardAnalogInput0(self) -> float:  # noqa: N802
        return self.c.analog_in(0)

    def getStandardAnalogInput1(self) -> float:  # noqa: N802
        return self.c.analog_in(1)

    def isConnected(self) -> bool:  # noqa: N802
        return self.c.connected

    def reconnect(self) -> bool:
        self.c.record("receive", "reconnect")
        if not (self.c.listening and self.c.reconnect_works):
            return False
        self.c.connected = True
        return True

    def disconnect(self) -> None:
        self.c.record("receive", "disconnect")


class FakeIO:
    """rtde_io.RTDEIOInterface."""

    def __init__(self, controller: FakeController, host: str = "192.0.2.10") -> None:
        _refuse_if_nothing_listens(controller, host)
        self.c = controller
        self.c.record("io", "__init__", host)

    def setAnalogOutputVoltage(self, output_id: int, voltage_ratio: float) -> bool:  # noqa: N802
        self.c.record("io", "setAnalogOutputVoltage", output_id, voltage_ratio)
        if not self.c.connected:
            return False
        self.c.set_analog(output_id, voltage_ratio)
        return True

    def isConnected(self) -> bool:  # noqa: N802
        return self.c.connected

    def disconnect(self) -> None:
        self.c.record("io", "disconnect")


class FakeDashboard:
    """dashboard_client.DashboardClient (constructing it does not connect; connect() does)."""

    def __init__(self, controller: FakeController, host: str = "192.0.2.10",
                 port: int = 29999) -> None:
        self.c = controller
        self._connected = False

    def connect(self, timeout_ms: int = 2000) -> None:
        self.c.record("dashboard", "connect", timeout_ms)
        if not self.c.listening:
            raise RuntimeError("Timeout connecting to UR dashboard server.")
        self._connected = True

    def isConnected(self) -> bool:  # noqa: N802
        return self._connected

    def polyscopeVersion(self) -> str:  # noqa: N802
        return "URSoftware 5.11.1.108318 (Aug 24 2021)"

    def getRobotModel(self) -> str:  # noqa: N802
        return "UR5"

    def getSerialNumber(self) -> str:  # noqa: N802
        return "20195500042"

    def isInRemoteControl(self) -> bool:  # noqa: N802
        return True

    def robotmode(self) -> str:
        return "Robotmode: RUNNING"

    def safetystatus(self) -> str:
        if self.c.emergency_stopped:
            return "Safetystatus: ROBOT_EMERGENCY_STOP"
        return "Safetystatus: PROTECTIVE_STOP" if self.c.protective_stopped else "Safetystatus: NORMAL"

    def disconnect(self) -> None:
        self.c.record("dashboard", "disconnect")
