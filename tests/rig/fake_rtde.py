"""Fakes of the ur_rtde interfaces with the same method names and failure habits.

One `FakeController` is the robot; `FakeControl`, `FakeReceive`, `FakeIO` and `FakeDashboard`
are the four ur_rtde objects talking to it. Like the real ones:

- construction raises RuntimeError when nothing listens (`controller.listening = False`);
- commands return False instead of raising (protective stop, dead control script, drop);
- an asynchronous `moveL` returns at once; `getAsyncOperationProgressEx()` carries an operation
  id that moves on when a move starts, and a "running" bit while it runs;
- the speed slider (`getTargetSpeedFraction`) and the trajectory limiter (`getSpeedScaling`)
  stretch moves in time; `getSpeedScalingCombined` is their product, 0 while paused;
- the controller time (`getTimestamp`) advances in 2 ms ticks (500 Hz), on its own origin.

Time comes from a `FakeClock` shared with the code under test, so runs are deterministic and
fast. Every call is recorded in `controller.calls` as (interface, method, args). The method
names and signatures are checked against the installed ur_rtde (test_fakes_match_sdk.py); the
emulated controller in tests/hardware_emulator is what checks the behaviour.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
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
RUNTIME_STOPPED, RUNTIME_PLAYING, RUNTIME_PAUSED = 1, 2, 4


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
    paused: bool = False
    protective_stopped: bool = False
    emergency_stopped: bool = False
    speed_slider: float = 1.0  # the pendant's slider (target_speed_fraction)
    limiter_scaling: float = 1.0  # the trajectory limiter (speed_scaling)
    robot_mode: int = ROBOT_MODE_RUNNING
    polyscope: str = "URSoftware 5.11.1.108318 (Aug 24 2021)"
    remote_control: bool = True
    reach_m: float = 0.85  # isPoseWithinSafetyLimits: inside this sphere around the base
    reconnect_works: bool = True
    # Failure injection: on the n-th moveL (1-based), `what` happens `after_s` into the move.
    fail_on_move: int | None = None
    fail_what: str = "protective_stop"  # "protective_stop" | "emergency_stop" | "drop"
    fail_after_s: float = 0.05
    analog_out: list[float] = field(default_factory=lambda: [0.0, 0.0])  # ratios of the span
    analog_domain: list[str] = field(default_factory=lambda: ["voltage", "voltage"])
    regulator_tau_s: float = 0.5  # the vacuum regulator follows the analog output like this
    regulator_gain: float = 1.0  # monitor signal per command signal (1 = perfect regulator)
    regulator_output_channel: int = 1  # the analog output that drives the regulator
    regulator_input_channel: int = 0  # the analog input its monitor output is wired to
    calls: list[tuple[str, str, tuple[Any, ...]]] = field(default_factory=list)
    on_tick: Callable[[FakeController], None] | None = None  # e.g. a piano watching the TCP
    _move: _Move | None = None
    _moves_started: int = 0
    _operation_id: int = 0
    _running: bool = False
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

    @property
    def speed_scaling(self) -> float:
        """How fast trajectories run: slider × limiter, 0 while paused."""
        return 0.0 if self.paused else self.speed_slider * self.limiter_scaling

    def runtime_state(self) -> int:
        if self.paused:
            return RUNTIME_PAUSED
        return RUNTIME_PLAYING if self.program_running else RUNTIME_STOPPED

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
        # Like the control script: the operation keeps its id, the running bit clears.
        self._move = None
        self._running = False

    def start_move(self, target: list[float], speed: float, acceleration: float) -> bool:
        self.update()
        if self._failed() or not self.program_running or self.paused:
            return False
        length = math.dist(self.pose[:3], target[:3])
        # Speed scaling slows the whole profile in time: v·s and a·s².
        profile = move_profile(max(length, 1e-12), speed, acceleration)
        duration = profile.duration_s / max(self.speed_scaling, 1e-9)
        self._moves_started += 1
        self._updated_at_s = -1.0
        self._move = _Move(list(self.pose), list(target), self.clock.now(), duration, profile)
        self._operation_id = (self._operation_id + 1) % 128
        self._running = True
        return True

    def status_word(self) -> int:
        """The control script's async status register (op id, running bit)."""
        self.update()
        return self._operation_id * 16777216 + (32768 if self._running else 0)

    def stop(self) -> None:
        self.update()
        if self._move is not None:
            self._finish_move()

    # -- analog I/O with a first-order regulator -------------------------------------------
    def set_analog(self, channel: int, ratio: float, domain: str = "voltage") -> None:
        self.analog_out[channel] = ratio
        self.analog_domain[channel] = domain
        if channel == self.regulator_output_channel:
            now = self.clock.now()
            volts = self._regulator_volts()
            self._regulator = (volts, self.analog_out_value(channel) * self.regulator_gain, now)

    def analog_out_value(self, channel: int) -> float:
        """Volts (0-10) or milliamps (4-20) the output drives."""
        ratio = self.analog_out[channel]
        return 4.0 + 16.0 * ratio if self.analog_domain[channel] == "current" else 10.0 * ratio

    def _regulator_volts(self) -> float:
        value, target, t0 = self._regulator
        dt = self.clock.now() - t0
        return target + (value - target) * math.exp(-dt / self.regulator_tau_s)

    def analog_in(self, channel: int) -> float:
        """The regulator's monitor output where it is wired: it repeats the command signal."""
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


def sdk_factories(controller: FakeController) -> dict[str, Callable[..., Any]]:
    """Stand-ins for the four SDK classes, called like them (host first), for `*_factory`."""
    return {
        "receive": partial(FakeReceive, controller),
        "control": partial(FakeControl, controller),
        "io": partial(FakeIO, controller),
        "dashboard": partial(FakeDashboard, controller),
    }


def _refuse_if_nothing_listens(controller: FakeController, host: str) -> None:
    if not controller.listening:
        raise RuntimeError(f"Error: Could not connect to: {host} at 30004, verify the IP")


class FakeAsyncStatus:
    """rtde_control.AsyncOperationStatus."""

    def __init__(self, arg0: int, /) -> None:
        self._value = arg0

    def value(self) -> int:
        return self._value

    def operationId(self) -> int:  # noqa: N802
        return (self._value >> 24) & 0x7F

    def isAsyncOperationRunning(self) -> bool:  # noqa: N802
        return bool(self._value & 0x8000)

    def progress(self) -> int:
        return self._value & 0x7FFF if self.isAsyncOperationRunning() else -1

    def changeCount(self) -> int:  # noqa: N802
        return (self._value >> 16) & 0xFF


class FakeControl:
    """rtde_control.RTDEControlInterface."""

    def __init__(self, controller: FakeController, hostname: str,
                 frequency: float = -1.0) -> None:
        _refuse_if_nothing_listens(controller, hostname)
        self.c = controller
        self.c.record("control", "__init__", hostname, frequency)

    def moveL(self, pose: list[float], speed: float = 0.25, acceleration: float = 1.2,  # noqa: N802
              asynchronous: bool = False) -> bool:
        self.c.record("control", "moveL", list(pose), speed, acceleration, asynchronous)
        if not self.c.start_move(list(pose), speed, acceleration):
            return False
        if asynchronous:
            return True
        while self.c.status_word() & 0x8000:  # blocking: let the clock run until the move ends
            self.c.clock.sleep(CONTROLLER_PERIOD_S)
        return not self.c._failed()

    def stopL(self, a: float = 10.0, asynchronous: bool = False) -> None:  # noqa: N802
        self.c.record("control", "stopL", a, asynchronous)
        self.c.stop()

    def getAsyncOperationProgressEx(self) -> FakeAsyncStatus:  # noqa: N802
        return FakeAsyncStatus(self.c.status_word())

    def isPoseWithinSafetyLimits(self, arg0: list[float], /) -> bool:  # noqa: N802
        self.c.record("control", "isPoseWithinSafetyLimits", list(arg0))
        if not (self.c.connected and self.c.program_running and not self.c.paused):
            return False  # ur_rtde answers False when the script cannot answer
        return math.hypot(*arg0[:3]) <= self.c.reach_m

    def isConnected(self) -> bool:  # noqa: N802
        return self.c.connected

    def isProgramRunning(self) -> bool:  # noqa: N802
        self.c.update()
        return self.c.connected and self.c.program_running and not self.c.paused

    def reconnect(self) -> bool:
        self.c.record("control", "reconnect")
        if not (self.c.listening and self.c.reconnect_works):
            return False
        self.c.connected = True
        if not (self.c.protective_stopped or self.c.emergency_stopped):
            self.c.program_running = True  # reconnecting re-uploads the control script
            self.c.paused = False
        return True

    def reuploadScript(self) -> bool:  # noqa: N802
        self.c.record("control", "reuploadScript")
        if not self.c.connected:
            return False
        if not (self.c.protective_stopped or self.c.emergency_stopped):
            self.c.program_running = True
            self.c.paused = False
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

    def __init__(self, controller: FakeController, hostname: str,
                 frequency: float = -1.0, variables: list[str] = []) -> None:  # noqa: B006
        _refuse_if_nothing_listens(controller, hostname)
        self.c = controller
        self.c.record("receive", "__init__", hostname, frequency)

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
        return 0.0 if self.c.paused else self.c.limiter_scaling

    def getTargetSpeedFraction(self) -> float:  # noqa: N802
        return self.c.speed_slider

    def getSpeedScalingCombined(self) -> float:  # noqa: N802
        return self.c.speed_scaling

    def getRuntimeState(self) -> int:  # noqa: N802
        return self.c.runtime_state()

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

    def getStandardAnalogOutput0(self) -> float:  # noqa: N802
        return self.c.analog_out_value(0)

    def getStandardAnalogOutput1(self) -> float:  # noqa: N802
        return self.c.analog_out_value(1)

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

    def __init__(self, controller: FakeController, hostname: str,
                 verbose: bool = False) -> None:
        _refuse_if_nothing_listens(controller, hostname)
        self.c = controller
        self.c.record("io", "__init__", hostname)

    def setAnalogOutputVoltage(self, arg0: int, arg1: float, /) -> bool:  # noqa: N802
        self.c.record("io", "setAnalogOutputVoltage", arg0, arg1)
        if not self.c.connected:
            return False
        self.c.set_analog(arg0, arg1, "voltage")
        return True

    def setAnalogOutputCurrent(self, arg0: int, arg1: float, /) -> bool:  # noqa: N802
        self.c.record("io", "setAnalogOutputCurrent", arg0, arg1)
        if not self.c.connected:
            return False
        self.c.set_analog(arg0, arg1, "current")
        return True

    def isConnected(self) -> bool:  # noqa: N802
        return self.c.connected

    def reconnect(self) -> bool:
        self.c.record("io", "reconnect")
        return self.c.listening and self.c.reconnect_works

    def disconnect(self) -> None:
        self.c.record("io", "disconnect")


class FakeDashboard:
    """dashboard_client.DashboardClient (constructing it does not connect; connect() does)."""

    def __init__(self, controller: FakeController, hostname: str,
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
        # ur_rtde returns the version number found in the server's answer.
        found = re.search(r"\d+\.\d+\.\d+\.\d+", self.c.polyscope)
        return found.group(0) if found else self.c.polyscope

    def getRobotModel(self) -> str:  # noqa: N802
        return "UR5"

    def getSerialNumber(self) -> str:  # noqa: N802
        if not self.c.polyscope.startswith("URSoftware 5"):
            raise RuntimeError("getSerialNumber() function is not supported on the dashboard "
                               "server for PolyScope versions less than 5.6.0")
        return "20195500042"

    def isInRemoteControl(self) -> bool:  # noqa: N802
        return self.c.remote_control

    def robotmode(self) -> str:
        return "Robotmode: RUNNING"

    def programState(self) -> str:  # noqa: N802
        names = {RUNTIME_STOPPED: "STOPPED", RUNTIME_PLAYING: "PLAYING", RUNTIME_PAUSED: "PAUSED"}
        return f"{names[self.c.runtime_state()]} <unnamed>"

    def safetystatus(self) -> str:
        if self.c.emergency_stopped:
            return "Safetystatus: ROBOT_EMERGENCY_STOP"
        return "Safetystatus: PROTECTIVE_STOP" if self.c.protective_stopped else "Safetystatus: NORMAL"

    def disconnect(self) -> None:
        self.c.record("dashboard", "disconnect")
