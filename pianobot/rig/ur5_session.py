"""Taking the UR5 and keeping it: pre-flight checks, the links, recovering a dropped one.

Opening order: the dashboard (PolyScope version → controller generation → RTDE rate), the
receive interface (read-only), the pre-flight check, and only then the control interface,
which uploads ur_rtde's control script and so takes the arm. The pre-flight check refuses a
robot that is stopped, not running, paused by someone at the pendant, or (e-Series) in local
control, and turns what would silently distort the data into warnings shown before any motion:
a speed slider below 100 % (every move slower than commanded), a trajectory limiter below 1.

Recovering (`reconnect`): a link that dropped is re-opened with ur_rtde's `reconnect()` (which
re-uploads the script as needed); a control script that ended while the links stayed up is
re-uploaded with `reuploadScript()` — `reconnect()` on a live link opens a second RTDE
session that fights the first for its registers. A paused program is never re-uploaded over:
the operator paused it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

from pianobot.rig.errors import ConnectionLost, DeviceUnavailable, RigError
from pianobot.rig.ur5_link import (
    ControllerInfo,
    choose_rate,
    open_control,
    open_dashboard,
    open_receive,
    quietly,
    read_controller,
)
from pianobot.rig.ur5_status import failure, read_status, settled_status
from pianobot.spec.rig import UR5Config

SCRIPT_START_TIMEOUT_S = 5.0  # ur_rtde's own wait for its script
IO_RELEASE_S = 0.1


@dataclass
class Links:
    """The ur_rtde objects of one arm, and what was learnt while opening them."""

    control: Any
    receive: Any
    dashboard: Any = None
    controller: ControllerInfo | None = None
    rate_hz: float | None = None
    warnings: list[str] = field(default_factory=list)


def slider_warnings(config: UR5Config, status: Any) -> list[str]:
    """What the controller's speed settings will do to every move, said before any motion."""
    warnings = []
    slider = status.speed_slider
    if slider is not None and slider < config.warn_speed_slider_below - 1e-9:
        warnings.append(
            f"the teach pendant's speed slider is at {100 * slider:.0f} %: every move runs at "
            f"{100 * slider:.0f} % of the commanded speed (accelerations at "
            f"{100 * slider * slider:.0f} %), so the keystrokes are not the planned ones; set "
            "it to 100 % before the run"
        )
    limiter = status.speed_scaling
    if limiter is not None and 0.0 < limiter < 1.0 - 1e-6 and not status.paused:
        warnings.append(
            f"the controller's trajectory limiter scales motion to {limiter:.2f} (reduced mode "
            "or a limit nearby): moves run slower than commanded"
        )
    return warnings


def preflight(config: UR5Config, receive: Any, dashboard: Any,
              controller: ControllerInfo) -> list[str]:
    """Refuse a robot that cannot be taken safely; return the warnings to show before motion."""
    status = read_status(receive)
    host = config.host
    if status.stopped or status.paused or (
        status.robot_mode is not None and status.robot_mode != 7
    ):
        reason = failure("taking the arm", status)
        raise DeviceUnavailable(f"UR5 at {host}: {reason}")
    if controller.major >= 5 and controller.minor >= 6:
        try:
            remote = bool(dashboard.isInRemoteControl())
        except RuntimeError:
            remote = True  # not answered: ur_rtde's own check will speak
        if not remote:
            raise DeviceUnavailable(
                f"UR5 at {host}: the teach pendant is in local control; switch it to Remote "
                "Control so ur_rtde may upload its control script"
            )
    return slider_warnings(config, status)


def open_links(config: UR5Config, *, receive_factory: Any = None, control_factory: Any = None,
               dashboard_factory: Any = None) -> Links:
    """Dashboard, receive, pre-flight, control; on failure everything opened is closed again."""
    host, timeout = config.host, config.connect_timeout_s
    dashboard = open_dashboard(host, timeout, dashboard_factory)
    receive = None
    try:
        controller = read_controller(dashboard, host)
        rate, warnings = choose_rate(config.frequency_hz, controller)
        receive = open_receive(host, rate, timeout, receive_factory)
        warnings += preflight(config, receive, dashboard, controller)
        control = open_control(host, rate, timeout, control_factory)
    except (RigError, ValueError, RuntimeError) as exc:
        for link in (receive, dashboard):
            quietly(link, "disconnect")
        if isinstance(exc, RigError):
            raise
        raise DeviceUnavailable(f"UR5 at {host}: {exc}") from exc
    return Links(control, receive, dashboard, controller, rate, warnings)


def reconnect(links: Links, io: Any, host: str) -> None:
    """Re-open what dropped, re-upload a control script that ended; raise what stays wrong.

    Raises ConnectionLost while a link stays down (the runner retries), SafetyStop when an
    operator must act (a stop, a paused program).
    """
    dropped = False
    try:
        if not links.receive.isConnected():
            dropped = True
            if not links.receive.reconnect():
                raise ConnectionLost(f"arm: RTDE receive did not reconnect to {host}")
    except RuntimeError as exc:
        raise ConnectionLost(f"arm: RTDE receive reconnect failed: {exc}") from exc
    control = links.control
    try:
        if not control.isConnected():
            dropped = True
            # Stop the client's own receive thread first: it retries the link by itself, and a
            # reconnect() racing it corrupted ur_rtde's heap (malloc abort) on a dropped link.
            quietly(control, "disconnect")
            if not control.reconnect():  # re-uploads the control script as needed
                raise ConnectionLost(f"arm: RTDE control did not reconnect to {host}")
        elif not control.isProgramRunning():
            status = settled_status(links.receive, control, 1.0 / (links.rate_hz or 125.0))
            if status.stopped or status.paused or status.link_down:
                raise failure("reconnect", status)
            if not control.reuploadScript():
                raise ConnectionLost(f"arm: re-uploading the control script to {host} failed")
            _wait_for_script(control, host)
    except RuntimeError as exc:
        raise ConnectionLost(f"arm: RTDE control reconnect failed: {exc}") from exc
    if io is not None and (dropped or not quietly(io, "isConnected")):
        cycle_io(io, host)
    status = settled_status(links.receive, control, 1.0 / (links.rate_hz or 125.0))
    if status.stopped or status.link_down or status.paused or status.script_stopped:
        raise failure("reconnect", status)


def cycle_io(io: Any, host: str) -> None:
    """Close and re-open the I/O link. It has no receive thread, so it never notices a drop:
    its next write would go nowhere (or raise). The pause lets the controller release its
    input registers before the new session claims them."""
    quietly(io, "disconnect")
    time.sleep(IO_RELEASE_S)
    try:
        if not io.reconnect():
            raise ConnectionLost(f"arm: RTDE I/O did not reconnect to {host}")
    except RuntimeError as exc:
        raise ConnectionLost(f"arm: RTDE I/O reconnect failed: {exc}") from exc


def close_link(link: Any) -> None:
    """Disconnect a ur_rtde object so that its destructor has nothing left to send: a
    disconnect that fails on a dead socket leaves it 'connected', and its destructor's own
    disconnect would then throw past C++ and end the process. Never raises."""
    if link is None:
        return
    try:
        link.disconnect()
    except Exception:  # a dead socket: give it a live one, then close that cleanly
        if quietly(link, "reconnect"):
            quietly(link, "disconnect")


def _wait_for_script(control: Any, host: str) -> None:
    deadline = time.monotonic() + SCRIPT_START_TIMEOUT_S
    while not control.isProgramRunning():
        if time.monotonic() > deadline:
            raise ConnectionLost(
                f"arm: the re-uploaded control script did not start on {host} within "
                f"{SCRIPT_START_TIMEOUT_S:g} s"
            )
        time.sleep(0.01)
