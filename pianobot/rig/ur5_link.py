"""Reaching a UR controller over ur_rtde, and reading why it refused a command.

ur_rtde's constructors raise RuntimeError when nothing listens, but a host that silently drops
packets can keep a TCP connect hanging for minutes; so every connection is preceded by a plain
socket probe with a short timeout. The vendor modules are imported here, lazily, so the
simulated rig runs without them.

The RTDE rate follows the controller like ur_rtde's own default (frequency -1): 125 Hz on a
CB3 (its control loop runs at 125 Hz), 500 Hz on an e-Series. pianobot reads the controller's
PolyScope version from the dashboard server first, so it knows the rate it asked for.

What the controller says about itself, and what a refused command means, is `ur5_status`.
"""

from __future__ import annotations

import importlib
import re
import socket
from dataclasses import dataclass
from typing import Any

from pianobot.rig.errors import DeviceUnavailable

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


def quietly(obj: Any, method: str, *args: Any) -> Any:
    """Call obj.method(*args); None if obj is None or the call fails (status reads while
    diagnosing, cleanup, metadata: none of them may mask the real error)."""
    if obj is None:
        return None
    try:
        return getattr(obj, method)(*args)
    except Exception:  # a dead link may raise anything
        return None
