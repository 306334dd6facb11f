"""The emulated UR controller: robot state, one control cycle, RTDE inputs and outputs.

Everything here runs under one lock: the cycle thread steps it, the network thread writes
client inputs and dashboard commands into it, the test thread injects faults. Its clock is the
cycle counter (125 Hz on a CB3, 500 Hz on an e-Series), so the RTDE `timestamp` advances by
exactly one period per cycle, like a real controller's.
"""

from __future__ import annotations

import math
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from .motion import LinearMove, Pose, Stop
from .regulator import UR_SPAN, VOLTAGE, VacuumRegulator, ur_value
from .script import ControlScript

CB3, ESERIES = "cb3", "e-series"
VERSIONS = {CB3: (3, 15, 7, 106331), ESERIES: (5, 11, 1, 108318)}
POLYSCOPE = {CB3: "URSoftware 3.15.7.106331 (Feb 02 2022)",
             ESERIES: "URSoftware 5.11.1.108318 (Aug 24 2021)"}
LOOP_HZ = {CB3: 125.0, ESERIES: 500.0}
# runtime_state
STOPPING, STOPPED, PLAYING, PAUSING, PAUSED, RESUMING = range(6)
RUNTIME_NAMES = {STOPPING: "STOPPING", STOPPED: "STOPPED", PLAYING: "PLAYING", PAUSING: "PAUSING",
                 PAUSED: "PAUSED", RESUMING: "RESUMING"}
# robot_mode
POWER_OFF, POWER_ON, IDLE, RUNNING = 3, 4, 5, 7
ROBOT_MODE_NAMES = {POWER_OFF: "POWER_OFF", POWER_ON: "POWER_ON", IDLE: "IDLE", RUNNING: "RUNNING"}
# safety_mode
NORMAL, PROTECTIVE, ROBOT_ESTOP = 1, 3, 7
SAFETY_NAMES = {NORMAL: "NORMAL", PROTECTIVE: "PROTECTIVE_STOP", ROBOT_ESTOP: "ROBOT_EMERGENCY_STOP"}
SLIDER_RATE_PER_S = 10.0  # the time scaling ramps (a pause decelerates, a resume accelerates)
PROGRAM_STOP_DECELERATION_MPS2 = 5.0
TRUTH_CYCLES = 120_000  # ground truth kept for the last 4 min at 500 Hz


@dataclass
class ControllerConfig:
    """What kind of robot the emulator is, and how it starts."""

    generation: str = ESERIES  # "cb3" | "e-series"
    model: str = "UR5"
    serial_number: str = "20195500042"
    start_pose: Pose = (-0.5, -0.1, 0.2, 0.0, math.pi, 0.0)
    reach_m: float = 0.85  # isPoseWithinSafetyLimits: within this distance of the base
    speed_slider: float = 1.0  # the pendant's slider (target_speed_fraction)
    limiter_scaling: float = 1.0  # the trajectory limiter's speed_scaling
    remote_control: bool = True
    unlock_delay_s: float = 0.0  # a real controller refuses to unlock a protective stop for 5 s
    regulator: VacuumRegulator | None = field(default_factory=VacuumRegulator)
    analog_input_domains: tuple[str, str] = (VOLTAGE, VOLTAGE)

    @property
    def version(self) -> tuple[int, int, int, int]:
        return VERSIONS[self.generation]

    @property
    def loop_hz(self) -> float:
        return LOOP_HZ[self.generation]


@dataclass
class MoveFault:
    """Do `what` once the n-th move started from now has covered `fraction` of its path."""

    nth: int
    fraction: float
    what: Callable[[], None]
    motion: LinearMove | None = None


class Controller:
    """The robot and its control box."""

    def __init__(self, config: ControllerConfig) -> None:
        self.config = config
        self.lock = threading.RLock()
        self.period_s = 1.0 / config.loop_hz
        self.cycle = 0
        self.epoch_s = 1234.5  # controller uptime at cycle 0
        self.pose: Pose = tuple(config.start_pose)  # type: ignore[assignment]
        self.velocity = (0.0,) * 6
        self.motion: LinearMove | Stop | None = None
        self.time_scale = config.speed_slider * config.limiter_scaling
        self.hold = 1.0  # 1 while the program plays, ramps to 0 while it pauses
        self.slider = config.speed_slider
        self.limiter = config.limiter_scaling
        self.robot_mode = RUNNING
        self.safety_mode = NORMAL
        self.protective_since_s: float | None = None
        self.runtime = STOPPED
        self.script: ControlScript | None = None
        self.teach_mode = False
        self.in_int = [0] * 48
        self.in_double = [0.0] * 48
        self.out_int = [0] * 48
        self.out_double = [0.0] * 48
        self.digital_out = 0
        self.analog_domain = [VOLTAGE, VOLTAGE]
        self.analog_ratio = [0.0, 0.0]
        self.regulator = config.regulator
        # What happened, for tests.
        self.commands: list[int] = []
        self.unsupported: list[int] = []
        self.programs: list[str] = []
        self.events: list[str] = []
        self.moves_started = 0
        self.truth: deque[tuple[float, Pose]] = deque(maxlen=TRUTH_CYCLES)
        self.faults: list[MoveFault] = []
        self.cycle_hooks: list[Callable[[Controller], None]] = []

    # -- the clock ---------------------------------------------------------------------------
    @property
    def timestamp(self) -> float:
        return self.epoch_s + self.cycle * self.period_s

    # -- one cycle ---------------------------------------------------------------------------
    def step(self) -> None:
        """One control cycle: the program's main loop and threads, then the motion."""
        self.cycle += 1
        if self.runtime == PLAYING and self.script is not None:
            self.script.step()
            if self.script.terminated:
                self._program_ended("the control script returned")
        self._move(self.period_s)
        if self.regulator is not None:
            ch = self.regulator.output_channel
            self.regulator.step(self.period_s, self.analog_domain[ch],
                                ur_value(self.analog_domain[ch], self.analog_ratio[ch]))
        self._check_faults()
        for hook in self.cycle_hooks:
            hook(self)
        self.truth.append((self.timestamp, self.pose))

    def _move(self, dt_s: float) -> None:
        # A pause ramps the trajectory's time scaling down (PAUSING, then PAUSED), a resume
        # ramps it up again (RESUMING, then PLAYING); the controller reports it in
        # speed_scaling. A protective stop halts at once.
        step = SLIDER_RATE_PER_S * dt_s
        if self.runtime == PAUSING:
            self.hold = max(self.hold - step, 0.0)
            if self.hold == 0.0:
                self.runtime = PAUSED
        elif self.runtime == RESUMING:
            self.hold = min(self.hold + step, 1.0)
            if self.hold == 1.0:
                self.runtime = PLAYING
        elif self.runtime == PLAYING:
            self.hold = 1.0
        else:  # no program: nothing moves but a stop already under way
            self.hold = 0.0
        self.time_scale = self.slider * self.limiter * self.hold
        motion = self.motion
        before = self.pose
        if isinstance(motion, LinearMove) and not motion.done:
            motion.advance(dt_s * self.time_scale)
            self.pose = motion.pose()
        elif isinstance(motion, Stop) and not motion.done and self.safety_mode == NORMAL:
            motion.advance(dt_s)
            self.pose = motion.pose()
        self.velocity = tuple((a - b) / dt_s for a, b in zip(self.pose, before, strict=True))

    # -- motion commands (called by the control script) -------------------------------------
    def start_move(self, target: tuple[float, ...], speed: float, acceleration: float) -> LinearMove:
        self.moves_started += 1
        motion = LinearMove(self.pose, target, speed, acceleration)
        self.motion = motion
        for fault in self.faults:
            fault.nth -= 1
            if fault.nth == 0:
                fault.motion = motion
        return motion

    def start_stop(self, deceleration: float) -> Stop:
        speed = math.sqrt(sum(v * v for v in self.velocity[:3]))
        direction = [v / speed for v in self.velocity[:3]] if speed > 0 else [0.0, 0.0, 0.0]
        self.motion = Stop(self.pose, direction, speed, deceleration)
        return self.motion

    def within_safety_limits(self, pose: tuple[float, ...]) -> bool:
        return math.hypot(*pose[:3]) <= self.config.reach_m and pose[2] > -0.1

    def tool_speed(self) -> float:
        return math.sqrt(sum(v * v for v in self.velocity[:3]))

    # -- programs ----------------------------------------------------------------------------
    def load_program(self, text: str) -> None:
        """A URScript program arrived on a script port: it replaces the running one."""
        self.programs.append(text)
        if self.script is not None:
            self.script.terminate()
            self._program_ended("replaced by a new program")
        if self.robot_mode != RUNNING or self.safety_mode != NORMAL:
            self.events.append("program refused: the robot is not running")
            return
        if self.config.generation == ESERIES and not self.config.remote_control:
            self.events.append("program refused: local control")
            return
        if not text.lstrip().startswith("def rtde_control"):
            self.events.append("program ignored: not ur_rtde's control script")
            return
        self.script = ControlScript(self, text)
        self.runtime = PLAYING

    def _program_ended(self, why: str) -> None:
        self.events.append(f"program ended: {why}")
        self.script = None
        self.runtime = STOPPED
        if isinstance(self.motion, LinearMove) and not self.motion.done:
            self.start_stop(PROGRAM_STOP_DECELERATION_MPS2)

    def stop_program(self) -> bool:
        if self.script is None:
            return False
        self.script.terminate()
        self._program_ended("stopped from the dashboard")
        return True

    def pause_program(self) -> bool:
        if self.runtime not in (PLAYING, RESUMING):
            return False
        self.runtime = PAUSING
        self.events.append("program paused")
        return True

    def play_program(self) -> bool:
        if self.runtime not in (PAUSED, PAUSING) or self.safety_mode != NORMAL:
            return False
        self.runtime = RESUMING
        self.events.append("program resumed")
        return True

    # -- safety ------------------------------------------------------------------------------
    def protective_stop(self, why: str = "injected") -> None:
        self.safety_mode = PROTECTIVE
        self.protective_since_s = self.timestamp
        self.events.append(f"protective stop: {why}")
        if self.runtime in (PLAYING, PAUSING, RESUMING):
            self.runtime = PAUSED

    def emergency_stop(self) -> None:
        self.safety_mode = ROBOT_ESTOP
        self.events.append("emergency stop")
        if self.script is not None:
            self.script.terminate()
            self._program_ended("emergency stop")
        self.motion = None

    def unlock_protective_stop(self) -> bool:
        if self.safety_mode != PROTECTIVE or self.protective_since_s is None:
            return False
        if self.timestamp - self.protective_since_s < self.config.unlock_delay_s:
            return False
        self.safety_mode = NORMAL
        self.protective_since_s = None
        return True

    def safety_status_bits(self) -> int:
        if self.safety_mode == PROTECTIVE:
            return 1 << 2
        if self.safety_mode == ROBOT_ESTOP:
            return (1 << 6) | (1 << 7)
        return 1 << 0

    def robot_status_bits(self) -> int:
        bits = 1 if self.robot_mode in (IDLE, RUNNING, POWER_ON) else 0
        if self.runtime == PLAYING:
            bits |= 1 << 1
        if self.teach_mode:
            bits |= 1 << 2
        return bits

    # -- faults ------------------------------------------------------------------------------
    def _check_faults(self) -> None:
        for fault in list(self.faults):
            motion = fault.motion
            if motion is None:
                continue
            s, _ = motion.profile.at(motion.tau_s)
            if motion.done or s >= fault.fraction * motion.profile.length_m:
                self.faults.remove(fault)
                fault.what()

    # -- RTDE inputs and outputs -------------------------------------------------------------
    def apply_inputs(self, values: dict[str, Any]) -> None:
        """A client's data package: registers, the speed slider, analog and digital outputs."""
        for name, value in values.items():
            if name.startswith("input_int_register_"):
                self.in_int[int(name.rsplit("_", 1)[1])] = int(value)
            elif name.startswith("input_double_register_"):
                self.in_double[int(name.rsplit("_", 1)[1])] = float(value)
        if values.get("speed_slider_mask") == 1 and "speed_slider_fraction" in values:
            self.slider = min(max(float(values["speed_slider_fraction"]), 0.0), 1.0)
        mask = int(values.get("standard_analog_output_mask", 0))
        kinds = int(values.get("standard_analog_output_type", 0))
        for ch in (0, 1):
            if mask >> ch & 1:
                # One domain bit per output (bit n: output n), 1 = voltage, 0 = current.
                self.analog_domain[ch] = VOLTAGE if kinds >> ch & 1 else "current"
                self.analog_ratio[ch] = float(values.get(f"standard_analog_output_{ch}", 0.0))
        dmask = int(values.get("standard_digital_output_mask", 0))
        if dmask:
            out = int(values.get("standard_digital_output", 0))
            self.digital_out = (self.digital_out & ~dmask) | (out & dmask)

    def analog_io_types(self) -> int:
        bits = 0
        for i, domain in enumerate(self.config.analog_input_domains):
            bits |= (domain == VOLTAGE) << i
        for ch in (0, 1):
            bits |= (self.analog_domain[ch] == VOLTAGE) << (2 + ch)
        return bits

    def analog_input(self, ch: int) -> float:
        reg = self.regulator
        if reg is not None and reg.monitor_channel == ch:
            value = reg.monitor_value()
            if reg.monitor_signal != self.config.analog_input_domains[ch]:
                return UR_SPAN[self.config.analog_input_domains[ch]][0]
            return value
        return 0.0

    def output(self, name: str) -> Any:
        """The value of one RTDE output field now."""
        getter = _GETTERS.get(name)
        if getter is not None:
            return getter(self)
        kind, _, index = name.rpartition("_")
        table = {"output_int_register": self.out_int, "output_double_register": self.out_double,
                 "input_int_register": self.in_int, "input_double_register": self.in_double}
        return table[kind][int(index)]


def _joints(c: Controller) -> tuple[float, ...]:
    # Not real inverse kinematics: a smooth, deterministic stand-in for the joint fields.
    x, y, z = c.pose[:3]
    return (math.atan2(y, x), -1.2 + z, 1.5 - z, -1.9, -1.57, 0.0)


_ZERO6 = (0.0,) * 6
_GETTERS: dict[str, Callable[[Controller], Any]] = {
    "timestamp": lambda c: c.timestamp,
    "target_q": _joints, "actual_q": _joints,
    "target_qd": lambda c: _ZERO6, "actual_qd": lambda c: _ZERO6, "target_qdd": lambda c: _ZERO6,
    "target_current": lambda c: _ZERO6, "actual_current": lambda c: _ZERO6,
    "target_moment": lambda c: _ZERO6, "joint_control_output": lambda c: _ZERO6,
    "actual_TCP_pose": lambda c: c.pose, "target_TCP_pose": lambda c: c.pose,
    "actual_TCP_speed": lambda c: c.velocity, "target_TCP_speed": lambda c: c.velocity,
    "actual_TCP_force": lambda c: _ZERO6,
    "actual_digital_input_bits": lambda c: 0,
    "joint_temperatures": lambda c: (31.0,) * 6,
    "actual_execution_time": lambda c: 0.3,
    "robot_mode": lambda c: c.robot_mode,
    "joint_mode": lambda c: (253,) * 6,
    "safety_mode": lambda c: c.safety_mode,
    "safety_status": lambda c: c.safety_mode,
    "actual_tool_accelerometer": lambda c: (0.0, 0.0, 9.81),
    # The limiter's scaling, which a pause ramps to 0 (and back); without a program: the limiter.
    "speed_scaling": lambda c: c.limiter * (c.hold if c.script is not None else 1.0),
    "target_speed_fraction": lambda c: c.slider,
    "actual_momentum": lambda c: 0.0,
    "actual_main_voltage": lambda c: 48.0, "actual_robot_voltage": lambda c: 48.0,
    "actual_robot_current": lambda c: 0.8, "actual_joint_voltage": lambda c: (48.0,) * 6,
    "actual_digital_output_bits": lambda c: c.digital_out,
    "runtime_state": lambda c: c.runtime,
    "elbow_position": lambda c: (0.0, 0.0, 0.5), "elbow_velocity": lambda c: (0.0, 0.0, 0.0),
    "robot_status_bits": lambda c: c.robot_status_bits(),
    "safety_status_bits": lambda c: c.safety_status_bits(),
    "analog_io_types": lambda c: c.analog_io_types(),
    "standard_analog_input0": lambda c: c.analog_input(0),
    "standard_analog_input1": lambda c: c.analog_input(1),
    "standard_analog_output0": lambda c: ur_value(c.analog_domain[0], c.analog_ratio[0]),
    "standard_analog_output1": lambda c: ur_value(c.analog_domain[1], c.analog_ratio[1]),
    "io_current": lambda c: 0.1,
    "tool_mode": lambda c: 0, "tool_analog_input_types": lambda c: 0,
    "tool_analog_input0": lambda c: 0.0, "tool_analog_input1": lambda c: 0.0,
    "tool_output_voltage": lambda c: 0, "tool_output_current": lambda c: 0.0,
    "tool_temperature": lambda c: 30.0, "tcp_force_scalar": lambda c: 0.0,
    "output_bit_registers0_to_31": lambda c: 0, "output_bit_registers32_to_63": lambda c: 0,
    "payload": lambda c: 0.3, "payload_cog": lambda c: (0.0, 0.0, 0.05),
    "payload_inertia": lambda c: _ZERO6, "ft_raw_wrench": lambda c: _ZERO6,
    "script_control_line": lambda c: 0,
}
