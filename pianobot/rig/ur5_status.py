"""What a UR controller says about itself, and what a refused ur_rtde command means.

ur_rtde reports failures as `False` (a protective stop, a dead or paused control script, a
timeout); `read_status` gathers what the controller says about itself so the caller can name
the cause (`failure`). Three speed figures are kept apart: the pendant's speed slider
(`getTargetSpeedFraction`), the trajectory limiter's scaling (`getSpeedScaling`) and their
product with pauses accounted for (`getSpeedScalingCombined`), the one that stretches moves.
The receive and control interfaces are two RTDE connections; `settled_status` re-reads until
they agree on the program state, so a diagnosis never mixes two controller cycles.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

from pianobot.rig.errors import ConnectionLost, RigError, SafetyStop
from pianobot.rig.ur5_link import quietly

# RTDE safety status bits (getSafetyStatusBits), bit number → name.
SAFETY_BITS: dict[int, str] = {
    0: "normal",
    1: "reduced",
    2: "protective stopped",
    3: "recovery",
    4: "safeguard stopped",
    5: "system emergency stopped",
    6: "robot emergency stopped",
    7: "emergency stopped",
    8: "violation",
    9: "fault",
    10: "stopped due to safety",
}
# Any of these needs an operator at the teach pendant: never retried.
STOP_BITS = frozenset({2, 4, 5, 6, 7, 8, 9, 10})
ROBOT_MODES: dict[int, str] = {
    -1: "NO_CONTROLLER", 0: "DISCONNECTED", 1: "CONFIRM_SAFETY", 2: "BOOTING", 3: "POWER_OFF",
    4: "POWER_ON", 5: "IDLE", 6: "BACKDRIVE", 7: "RUNNING", 8: "UPDATING_FIRMWARE",
}
ROBOT_MODE_RUNNING = 7
SAFETY_MODES: dict[int, str] = {
    1: "NORMAL", 2: "REDUCED", 3: "PROTECTIVE_STOP", 4: "RECOVERY", 5: "SAFEGUARD_STOP",
    6: "SYSTEM_EMERGENCY_STOP", 7: "ROBOT_EMERGENCY_STOP", 8: "VIOLATION", 9: "FAULT",
    10: "VALIDATE_JOINT_ID", 11: "UNDEFINED_SAFETY_MODE", 12: "AUTOMATIC_MODE_SAFEGUARD_STOP",
    13: "SYSTEM_THREE_POSITION_ENABLING_STOP",
}
STOP_SAFETY_MODES = frozenset({3, 5, 6, 7, 8, 9, 12, 13})
# RTDE runtime_state: the state of the program on the controller (ur_rtde's script, when ours).
RUNTIME_STATES: dict[int, str] = {
    0: "STOPPING", 1: "STOPPED", 2: "PLAYING", 3: "PAUSING", 4: "PAUSED", 5: "RESUMING",
}
RUNTIME_PLAYING = 2
RUNTIME_PAUSE_STATES = frozenset({3, 4, 5})


@dataclass(frozen=True)
class ArmStatus:
    """What the controller says about itself (read after a command returned False, and while
    a move runs)."""

    receive_connected: bool | None
    control_connected: bool | None
    program_running: bool | None
    protective_stopped: bool | None
    emergency_stopped: bool | None
    safety_status_bits: int | None
    robot_mode: int | None
    safety_mode: int | None
    runtime_state: int | None = None
    speed_slider: float | None = None  # the pendant's slider (target_speed_fraction)
    speed_scaling: float | None = None  # the trajectory limiter's scaling
    speed_scaling_combined: float | None = None  # slider × limiter, 0 while paused

    @property
    def safety_flags(self) -> tuple[str, ...]:
        """Names of the safety status bits that are set."""
        bits = self.safety_status_bits or 0
        return tuple(name for bit, name in SAFETY_BITS.items() if bits >> bit & 1)

    @property
    def stopped(self) -> bool:
        """A protective, safeguard or emergency stop (or a fault): an operator must act."""
        bits = self.safety_status_bits or 0
        return bool(
            self.protective_stopped
            or self.emergency_stopped
            or any(bits >> bit & 1 for bit in STOP_BITS)
            or (self.safety_mode in STOP_SAFETY_MODES)
        )

    @property
    def link_down(self) -> bool:
        """An RTDE link is gone (transient: reconnect and retry)."""
        return self.receive_connected is False or self.control_connected is False

    @property
    def paused(self) -> bool:
        """The program is paused (or pausing, or resuming) from the pendant or the dashboard."""
        return self.runtime_state in RUNTIME_PAUSE_STATES

    @property
    def consistent(self) -> bool:
        """The control and receive streams agree on the program state. They are two RTDE
        connections: for a cycle or two one may already show what the other does not yet."""
        if self.program_running is None or self.runtime_state is None or self.link_down:
            return True
        return self.program_running == (self.runtime_state == RUNTIME_PLAYING)

    @property
    def script_stopped(self) -> bool:
        """The control script is not running and not paused (ended, or stopped on the pendant):
        with the links up, re-uploading it is enough."""
        return self.program_running is False and not self.paused

    def text(self) -> str:
        """One line for an error message or a report."""
        parts = []
        if self.robot_mode is not None:
            parts.append(f"robot mode {ROBOT_MODES.get(self.robot_mode, self.robot_mode)}")
        if self.safety_mode is not None:
            parts.append(f"safety mode {SAFETY_MODES.get(self.safety_mode, self.safety_mode)}")
        if self.safety_status_bits is not None:
            parts.append(f"safety status {', '.join(self.safety_flags) or 'none'}")
        if self.runtime_state is not None:
            parts.append(f"program {RUNTIME_STATES.get(self.runtime_state, self.runtime_state)}")
        if self.speed_slider is not None:
            parts.append(f"speed slider {100 * self.speed_slider:.0f} %")
        if self.speed_scaling is not None and self.speed_scaling < 1.0 - 1e-6:
            parts.append(f"trajectory limiter {self.speed_scaling:.2f}")
        for label, flag in (
            ("receive link", self.receive_connected),
            ("control link", self.control_connected),
        ):
            if flag is False:
                parts.append(f"{label} down")
        if self.program_running is False and not self.paused:
            parts.append("control script not running")
        return "; ".join(parts) or "the controller gave no status"

    def to_dict(self) -> dict[str, Any]:
        """JSON-able, with decoded names."""
        def name(table: dict[int, str], value: int | None) -> Any:
            return table.get(value, value) if value is not None else None

        return {
            "robot_mode": name(ROBOT_MODES, self.robot_mode),
            "safety_mode": name(SAFETY_MODES, self.safety_mode),
            "safety_status": list(self.safety_flags),
            "program_state": name(RUNTIME_STATES, self.runtime_state),
            "speed_slider": self.speed_slider,
            "speed_scaling": self.speed_scaling,
            "speed_scaling_combined": self.speed_scaling_combined,
            "protective_stopped": self.protective_stopped,
            "emergency_stopped": self.emergency_stopped,
            "program_running": self.program_running,
        }


def _number(value: Any, kind: type) -> Any:
    return kind(value) if value is not None else None


def read_status(receive: Any, control: Any = None) -> ArmStatus:
    """Read every status getter that answers; never raises."""
    return ArmStatus(
        receive_connected=quietly(receive, "isConnected"),
        control_connected=quietly(control, "isConnected"),
        program_running=quietly(control, "isProgramRunning"),
        protective_stopped=quietly(receive, "isProtectiveStopped"),
        emergency_stopped=quietly(receive, "isEmergencyStopped"),
        safety_status_bits=_number(quietly(receive, "getSafetyStatusBits"), int),
        robot_mode=_number(quietly(receive, "getRobotMode"), int),
        safety_mode=_number(quietly(receive, "getSafetyMode"), int),
        runtime_state=_number(quietly(receive, "getRuntimeState"), int),
        speed_slider=_number(quietly(receive, "getTargetSpeedFraction"), float),
        speed_scaling=_number(quietly(receive, "getSpeedScaling"), float),
        speed_scaling_combined=_number(quietly(receive, "getSpeedScalingCombined"), float),
    )


def settled_status(receive: Any, control: Any, period_s: float, cycles: int = 25) -> ArmStatus:
    """read_status, re-read (a cycle apart, up to `cycles` times) until both streams agree."""
    status = read_status(receive, control)
    for _ in range(cycles):
        if status.consistent:
            break
        time.sleep(period_s)
        status = read_status(receive, control)
    return status


def failure(action: str, status: ArmStatus) -> RigError:
    """The error for a refused or failed command, chosen by what the controller reports.

    A stop needs an operator (SafetyStop, never retried), and so does a paused program (the
    operator paused it: re-uploading the script over it would undo that), a robot that is not
    running (powered off, brakes on) and a speed slider at 0. A dropped link is transient
    (ConnectionLost: reconnect and retry), and so is a control script that ended while the
    links stayed up (ConnectionLost: the reconnect re-uploads the script).
    """
    detail = f"{action} failed: {status.text()}"
    if status.stopped:
        return SafetyStop(f"{detail}; clear the stop on the teach pendant before resuming")
    if status.link_down:
        return ConnectionLost(detail)
    if status.paused:
        return SafetyStop(
            f"{detail}; the program was paused on the teach pendant: this keystroke is not "
            "valid; stop or resume the program there, then resume the run"
        )
    if status.robot_mode is not None and status.robot_mode != ROBOT_MODE_RUNNING:
        return SafetyStop(f"{detail}; the arm must be powered on with brakes released")
    if status.speed_slider is not None and status.speed_slider <= 0.0:
        return SafetyStop(f"{detail}; the speed slider is at 0 %")
    if status.script_stopped:
        return ConnectionLost(detail)
    return RigError(detail)
