"""Reaching a UR controller over ur_rtde, and reading why it refused a command.

ur_rtde's constructors raise RuntimeError when nothing listens, but a host that silently drops
packets can keep a TCP connect hanging for minutes; so every connection is preceded by a plain
socket probe with a short timeout. The vendor modules are imported here, lazily, so the
simulated rig runs without them.

ur_rtde reports failures as `False` (a protective stop, a dead control script, a timeout);
`read_status` gathers what the controller says about itself so the caller can name the cause.
"""

from __future__ import annotations

import importlib
import socket
from dataclasses import dataclass
from typing import Any

from pianobot.rig.errors import ConnectionLost, DeviceUnavailable, RigError, SafetyStop

RTDE_PORT = 30004  # RTDE: receive, control and I/O interfaces
DASHBOARD_PORT = 29999

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


def open_receive(host: str, frequency_hz: float, timeout_s: float, factory: Any = None) -> Any:
    """An `rtde_receive.RTDEReceiveInterface` (read-only: safe while someone else drives).

    `factory` replaces the SDK class (tests pass fakes; then no socket probe is made).
    """
    what = "UR RTDE receive"
    if factory is None:
        factory = _sdk("rtde_receive").RTDEReceiveInterface
        probe(host, RTDE_PORT, timeout_s, what)
    return _construct(what, host, RTDE_PORT, factory, float(frequency_hz))


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
    """A connected `dashboard_client.DashboardClient` (versions, safety status, popups)."""
    if factory is None:
        factory = _sdk("dashboard_client").DashboardClient
        probe(host, DASHBOARD_PORT, timeout_s, "UR dashboard server")
    client = factory(host)
    try:
        client.connect(int(timeout_s * 1000))
    except RuntimeError as exc:
        raise DeviceUnavailable(
            f"UR dashboard server at {host}:{DASHBOARD_PORT}: connect failed ({exc})"
        ) from exc
    return client


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
    """What the controller says about itself, read after a command returned False."""

    receive_connected: bool | None
    control_connected: bool | None
    program_running: bool | None
    protective_stopped: bool | None
    emergency_stopped: bool | None
    safety_status_bits: int | None
    robot_mode: int | None
    safety_mode: int | None
    speed_scaling: float | None

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
        """The RTDE link or the control script is gone (transient: reconnect and retry)."""
        return (
            self.receive_connected is False
            or self.control_connected is False
            or self.program_running is False
        )

    def text(self) -> str:
        """One line for an error message or a report."""
        parts = []
        if self.robot_mode is not None:
            parts.append(f"robot mode {ROBOT_MODES.get(self.robot_mode, self.robot_mode)}")
        if self.safety_mode is not None:
            parts.append(f"safety mode {SAFETY_MODES.get(self.safety_mode, self.safety_mode)}")
        if self.safety_status_bits is not None:
            parts.append(f"safety status {', '.join(self.safety_flags) or 'none'}")
        if self.speed_scaling is not None:
            parts.append(f"speed scaling {self.speed_scaling:.2f}")
        for label, flag in (
            ("receive link", self.receive_connected),
            ("control link", self.control_connected),
        ):
            if flag is False:
                parts.append(f"{label} down")
        if self.program_running is False:
            parts.append("control script not running")
        return "; ".join(parts) or "the controller gave no status"

    def to_dict(self) -> dict[str, Any]:
        """JSON-able, with decoded names."""
        return {
            "robot_mode": ROBOT_MODES.get(self.robot_mode, self.robot_mode)
            if self.robot_mode is not None else None,
            "safety_mode": SAFETY_MODES.get(self.safety_mode, self.safety_mode)
            if self.safety_mode is not None else None,
            "safety_status": list(self.safety_flags),
            "speed_scaling": self.speed_scaling,
            "protective_stopped": self.protective_stopped,
            "emergency_stopped": self.emergency_stopped,
            "program_running": self.program_running,
        }


def read_status(receive: Any, control: Any = None) -> ArmStatus:
    """Read every status getter that answers; never raises."""
    bits = _ask(receive, "getSafetyStatusBits")
    mode = _ask(receive, "getRobotMode")
    safety = _ask(receive, "getSafetyMode")
    scaling = _ask(receive, "getSpeedScaling")
    return ArmStatus(
        receive_connected=_ask(receive, "isConnected"),
        control_connected=_ask(control, "isConnected"),
        program_running=_ask(control, "isProgramRunning"),
        protective_stopped=_ask(receive, "isProtectiveStopped"),
        emergency_stopped=_ask(receive, "isEmergencyStopped"),
        safety_status_bits=int(bits) if bits is not None else None,
        robot_mode=int(mode) if mode is not None else None,
        safety_mode=int(safety) if safety is not None else None,
        speed_scaling=float(scaling) if scaling is not None else None,
    )


def failure(action: str, status: ArmStatus) -> RigError:
    """The error for a refused or failed command, chosen by what the controller reports.

    A stop needs an operator (SafetyStop, never retried); a dropped link or a dead control
    script is transient (ConnectionLost, reconnect and retry); a robot that is not running
    (powered off, brakes on, paused at speed 0) also needs an operator.
    """
    detail = f"{action} failed: {status.text()}"
    if status.stopped:
        return SafetyStop(f"{detail}; clear the stop on the teach pendant before resuming")
    if status.link_down:
        return ConnectionLost(detail)
    if status.robot_mode is not None and status.robot_mode != ROBOT_MODE_RUNNING:
        return SafetyStop(f"{detail}; the arm must be powered on with brakes released")
    if status.speed_scaling is not None and status.speed_scaling <= 0.0:
        return SafetyStop(f"{detail}; the program is paused (speed slider at 0)")
    return RigError(detail)
