"""Reaching a UR controller over ur_rtde, and reading why it refused a command.

ur_rtde's constructors raise RuntimeError when nothing listens, but a host that silently drops
packets can keep a TCP connect hanging for minutes; so every connection is preceded by a plain
socket probe with a short timeout. The vendor modules are imported here, lazily, so the
simulated rig runs without them.

The RTDE rate follows the controller like ur_rtde's own default (frequency -1): 125 Hz on a
CB3 (its control loop runs at 125 Hz), 500 Hz on an e-Series. pianobot reads the controller's
PolyScope version from the dashboard server first, so it knows the rate it asked for.

ur_rtde reports failures as `False` (a protective stop, a dead or paused control script, a
timeout); `read_status` gathers what the controller says about itself so the caller can name
the cause. Three speed figures are kept apart: the pendant's speed slider
(`getTargetSpeedFraction`), the trajectory limiter's scaling (`getSpeedScaling`) and their
product with pauses accounted for (`getSpeedScalingCombined`), the one that stretches moves.
"""

from __future__ import annotations

import importlib
import re
import socket
import time
from dataclasses import dataclass
from typing import Any

from pianobot.rig.errors import ConnectionLost, DeviceUnavailable, RigError, SafetyStop

RTDE_PORT = 30004  # RTDE: receive, control and I/O interfaces
DASHBOARD_PORT = 29999
CB3_RATE_HZ = 125.0  # a CB3's control loop, and the fastest RTDE stream it sends
ESERIES_RATE_HZ = 500.0

# What the receive interface streams: only the fields pianobot reads (ur_rtde's default recipe
# has ~60, at up to 500 Hz). A getter of a field not listed raises in ur_rtde.
RECEIVE_VARIABLES = [
    "timestamp", "actual_TCP_pose", "actual_TCP_speed", "robot_mode", "safety_mode",
    "safety_status_bits", "robot_status_bits", "runtime_state", "speed_scaling",
    "target_speed_fraction", "standard_analog_input0", "standard_analog_input1",
    "standard_analog_output0", "standard_analog_output1",
]

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
class ControllerInfo:
    """The controller's software generation, from its PolyScope version."""

    polyscope_version: str  # e.g. "5.11.1.108318"
    major: int
    minor: int

    @property
    def generation(self) -> str:
        return "CB3" if self.major < 5 else "e-Series"

    @property
    def loop_hz(self) -> float:
        """The control loop rate: the fastest an RTDE stream can go."""
        return CB3_RATE_HZ if self.major < 5 else ESERIES_RATE_HZ

    def to_dict(self) -> dict[str, Any]:
        return {"polyscope_version": self.polyscope_version, "generation": self.generation,
                "loop_hz": self.loop_hz}


_VERSION = re.compile(r"(\d+)\.(\d+)\.(\d+)(?:\.(\d+))?")


def parse_polyscope_version(text: str) -> ControllerInfo:
    """ControllerInfo from the dashboard's PolyscopeVersion answer ("URSoftware 5.11.1.108318 …")."""
    found = _VERSION.search(text or "")
    if found is None:
        raise DeviceUnavailable(f"UR dashboard server: unreadable PolyScope version {text!r}")
    return ControllerInfo(found.group(0), int(found.group(1)), int(found.group(2)))


def choose_rate(requested_hz: float | None, controller: ControllerInfo) -> tuple[float, list[str]]:
    """The RTDE rate to use and any warning: the rig file's, or the controller's loop rate."""
    if requested_hz is None:
        return controller.loop_hz, []
    if requested_hz > controller.loop_hz:
        return controller.loop_hz, [
            f"the rig file asks RTDE at {requested_hz:g} Hz, but a {controller.generation} "
            f"controller runs its loop at {controller.loop_hz:g} Hz: using {controller.loop_hz:g} Hz"
        ]
    return float(requested_hz), []


def probe(host: str, port: int, timeout_s: float, what: str) -> None:
    """Open and close a TCP connection; DeviceUnavailable with the reason when it fails."""
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            return
    except TimeoutError as exc:
        raise DeviceUnavailable(
            f"{what} at {host}:{port}: no answer within {timeout_s:g} s"
        ) from exc
    except OSError as exc:
        reason = exc.strerror or str(exc) or type(exc).__name__
        raise DeviceUnavailable(f"{what} at {host}:{port}: unreachable ({reason})") from exc


def _sdk(module: str) -> Any:
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise DeviceUnavailable(
            f"the UR5 backend needs the ur_rtde package (pip install 'pianobot[ur5]'): {exc}"
        ) from exc


def _construct(what: str, host: str, port: int, factory: Any, *args: Any) -> Any:
    try:
        return factory(host, *args)
    except RuntimeError as exc:
        raise DeviceUnavailable(f"{what} at {host}:{port}: ur_rtde could not connect ({exc})") from exc


def open_receive(
    host: str, frequency_hz: float, timeout_s: float, factory: Any = None,
    variables: list[str] | None = None,
) -> Any:
    """An `rtde_receive.RTDEReceiveInterface` streaming `variables` (default RECEIVE_VARIABLES).

    Read-only: safe while someone else drives. `factory` replaces the SDK class (tests pass
    fakes; then no socket probe is made).
    """
    what = "UR RTDE receive"
    if factory is None:
        factory = _sdk("rtde_receive").RTDEReceiveInterface
        probe(host, RTDE_PORT, timeout_s, what)
    names = list(RECEIVE_VARIABLES if variables is None else variables)
    return _construct(what, host, RTDE_PORT, factory, float(frequency_hz), names)


def open_control(host: str, frequency_hz: float, timeout_s: float, factory: Any = None) -> Any:
    """An `rtde_control.RTDEControlInterface` (uploads the control script: takes the arm)."""
    what = "UR RTDE control"
    if factory is None:
        factory = _sdk("rtde_control").RTDEControlInterface
        probe(host, RTDE_PORT, timeout_s, what)
    return _construct(what, host, RTDE_PORT, factory, float(frequency_hz))


def open_io(host: str, timeout_s: float, factory: Any = None) -> Any:
    """An `rtde_io.RTDEIOInterface` (analog and digital outputs)."""
    what = "UR RTDE I/O"
    if factory is None:
        factory = _sdk("rtde_io").RTDEIOInterface
        probe(host, RTDE_PORT, timeout_s, what)
    return _construct(what, host, RTDE_PORT, factory)


def open_dashboard(host: str, timeout_s: float, factory: Any = None) -> Any:
    """A connected `dashboard_client.DashboardClient` (versions, safety status, program state)."""
    if factory is None:
        factory = _sdk("dashboard_client").DashboardClient
        probe(host, DASHBOARD_PORT, timeout_s, "UR dashboard server")
    client = factory(host)
    try:
        client.connect(int(timeout_s * 1000))
        connected = bool(client.isConnected())
    except RuntimeError as exc:
        raise DeviceUnavailable(
            f"UR dashboard server at {host}:{DASHBOARD_PORT}: connect failed ({exc})"
        ) from exc
    if not connected:  # ur_rtde's connect() may return quietly on a timeout
        raise DeviceUnavailable(
            f"UR dashboard server at {host}:{DASHBOARD_PORT}: no answer within {timeout_s:g} s"
        )
    return client


def read_controller(dashboard: Any, host: str = "") -> ControllerInfo:
    """The controller's PolyScope version (DeviceUnavailable when the dashboard will not say)."""
    try:
        text = str(dashboard.polyscopeVersion())
    except RuntimeError as exc:
        raise DeviceUnavailable(f"UR dashboard server at {host}: no PolyScope version ({exc})") from exc
    return parse_polyscope_version(text)


def _ask(obj: Any, method: str) -> Any:
    """Call a status getter; None when the object lacks it or it fails (we are diagnosing)."""
    if obj is None:
        return None
    try:
        return getattr(obj, method)()
    except Exception:  # a dead link may raise anything; the diagnosis must still be made
        return None


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
        receive_connected=_ask(receive, "isConnected"),
        control_connected=_ask(control, "isConnected"),
        program_running=_ask(control, "isProgramRunning"),
        protective_stopped=_ask(receive, "isProtectiveStopped"),
        emergency_stopped=_ask(receive, "isEmergencyStopped"),
        safety_status_bits=_number(_ask(receive, "getSafetyStatusBits"), int),
        robot_mode=_number(_ask(receive, "getRobotMode"), int),
        safety_mode=_number(_ask(receive, "getSafetyMode"), int),
        runtime_state=_number(_ask(receive, "getRuntimeState"), int),
        speed_slider=_number(_ask(receive, "getTargetSpeedFraction"), float),
        speed_scaling=_number(_ask(receive, "getSpeedScaling"), float),
        speed_scaling_combined=_number(_ask(receive, "getSpeedScalingCombined"), float),
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
