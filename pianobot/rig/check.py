"""`pianobot rig check`: reach every device a lab rig file configures and report what it says.

Each device is checked in its own thread with the rig's short connect timeout, so a rig with
nothing on the network answers within a few seconds with one reason per device. Nothing is
commanded: the arm is read over RTDE receive and the dashboard only (the control interface
would take the arm over), the vacuum I/O is connected but no output is set.

The arm's report is what decides whether a run's data will be what was planned: controller
generation and the RTDE rate that follows from it (and the rate the stream really has), the
pendant's speed slider, the trajectory limiter and their combined scaling, safety status,
robot mode and program state. The vacuum's report is the regulator's declared signal and span
and, with a monitor, the pressure it reads now.
"""

from __future__ import annotations

import functools
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from pianobot.rig.clock import WallClock
from pianobot.rig.errors import RigError
from pianobot.rig.lab import command_span, monitor_span
from pianobot.rig.midi import MidiKeyboard, mido_backend
from pianobot.rig.ur5_link import (
    choose_rate,
    open_dashboard,
    open_io,
    open_receive,
    read_controller,
)
from pianobot.rig.ur5_session import slider_warnings
from pianobot.rig.ur5_status import read_status
from pianobot.spec.rig import RigSpec

GRACE_S = 3.0  # beyond the connect timeout, a check that has not answered is reported as hung


@dataclass(frozen=True)
class DeviceCheck:
    """The outcome for one device: reachable and usable (`ok`), a one-line summary, details."""

    device: str
    ok: bool
    summary: str
    details: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able."""
        return {"device": self.device, "ok": self.ok, "summary": self.summary, **self.details}


@dataclass(frozen=True)
class RigCheck:
    """Every device's outcome, in a fixed order."""

    host: str
    devices: tuple[DeviceCheck, ...]

    @property
    def ok(self) -> bool:
        """True when every device is reachable and usable."""
        return all(d.ok for d in self.devices)

    @property
    def failures(self) -> tuple[DeviceCheck, ...]:
        """The devices that are not."""
        return tuple(d for d in self.devices if not d.ok)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able."""
        return {"host": self.host, "ok": self.ok, "devices": [d.to_dict() for d in self.devices]}


def _disconnect(link: Any) -> None:
    try:
        link.disconnect()
    except Exception:  # the check is over; a failing disconnect changes nothing
        pass


#: The grid the stream's timestamp steps are read on (controller cycles are 2 or 8 ms).
RATE_TICK_S = 1e-4


def measured_rate_hz(receive: Any, window_s: float = 0.1, max_wait_s: float = 1.0) -> float | None:
    """The rate the RTDE stream really has: the period its timestamps step by.

    Reads for `window_s`, longer (up to `max_wait_s`) until 20 packages were seen. A busy host
    misses packages, so the steps seen are whole multiples of the period (the controller stamps
    each package with its cycle's time): the period is their greatest common divisor, on a
    0.1 ms grid. The smallest step alone was the period only once two consecutive packages were
    read; on a loaded host it read an e-Series stream at 250 Hz.
    """
    seen: list[float] = []
    start = time.monotonic()
    while len(seen) < 200:
        elapsed = time.monotonic() - start
        if elapsed >= max_wait_s or (elapsed >= window_s and len(seen) >= 20):
            break
        ts = float(receive.getTimestamp())
        if not seen or ts != seen[-1]:
            seen.append(ts)
        time.sleep(0.0005)
    ticks = [t for a, b in zip(seen, seen[1:], strict=False) if (t := round((b - a) / RATE_TICK_S)) > 0]
    return round(1.0 / (functools.reduce(math.gcd, ticks) * RATE_TICK_S), 1) if ticks else None


def check_arm(rig: RigSpec, factory: Any = None, dashboard_factory: Any = None) -> DeviceCheck:
    """Controller version and RTDE rate, speed slider and scaling, safety and program state."""
    assert rig.ur5 is not None
    ur5 = rig.ur5
    dashboard = open_dashboard(ur5.host, ur5.connect_timeout_s, dashboard_factory)
    try:
        controller = read_controller(dashboard, ur5.host)
        rate, warnings = choose_rate(ur5.frequency_hz, controller)
        program = _answer(dashboard, "programState")
        remote = _answer(dashboard, "isInRemoteControl") if controller.major >= 5 else None
        receive = open_receive(ur5.host, rate, ur5.connect_timeout_s, factory)
        try:
            status = read_status(receive)
            pose = [round(float(v), 5) for v in receive.getActualTCPPose()]
            measured = measured_rate_hz(receive)
        finally:
            _disconnect(receive)
    finally:
        _disconnect(dashboard)
    warnings += slider_warnings(ur5, status)
    source = "rig file" if ur5.frequency_hz is not None else f"{controller.generation} default"
    details = {
        **status.to_dict(), "controller": controller.to_dict(), "rtde_rate_hz": rate,
        "rtde_rate_source": source, "measured_rate_hz": measured, "dashboard_program": program,
        "remote_control": remote, "tcp_pose": pose, "warnings": warnings,
    }
    summary = (f"{ur5.host}: {controller.generation} (PolyScope {controller.polyscope_version}), "
               f"RTDE {rate:g} Hz ({source}"
               + (f", streaming at {measured:g} Hz" if measured else "") + f"); {status.text()}")
    if status.speed_scaling_combined is not None:
        summary += f"; combined scaling {status.speed_scaling_combined:.2f}"
    if status.stopped:
        return DeviceCheck("arm", False, f"{summary}; clear the stop on the teach pendant", details)
    if status.robot_mode is not None and status.robot_mode != 7:
        return DeviceCheck("arm", False, f"{summary}; power on and release the brakes", details)
    if status.paused:
        return DeviceCheck("arm", False, f"{summary}; a program is paused on the teach pendant: "
                           "stop it before a run", details)
    if remote is False:
        return DeviceCheck("arm", False, f"{summary}; switch the pendant to Remote Control",
                           details)
    for warning in warnings:
        summary += f" — warning: {warning}"
    return DeviceCheck("arm", True, summary, details)


def _answer(client: Any, method: str) -> Any:
    try:
        return getattr(client, method)()
    except Exception:  # CB3 controllers lack some queries: report what answers
        return None


def check_dashboard(rig: RigSpec, factory: Any = None) -> DeviceCheck:
    """Dashboard server: PolyScope version, model, serial number, safety status."""
    assert rig.ur5 is not None
    client = open_dashboard(rig.ur5.host, rig.ur5.connect_timeout_s, factory)
    details: dict[str, Any] = {}
    try:
        for key, method in (
            ("polyscope_version", "polyscopeVersion"), ("robot_model", "getRobotModel"),
            ("serial_number", "getSerialNumber"), ("robot_mode", "robotmode"),
            ("safety_status", "safetystatus"), ("program_state", "programState"),
        ):
            details[key] = _answer(client, method)
    finally:
        _disconnect(client)
    version = details.get("polyscope_version") or "unknown PolyScope version"
    summary = f"{version}, {details.get('robot_model') or 'unknown model'}"
    for key in ("safety_status", "program_state"):
        if details.get(key):
            summary += f", {details[key]}"
    return DeviceCheck("dashboard", True, summary, details)


def check_calibration(rig: RigSpec) -> DeviceCheck:
    """The reference pose is set and inside the workspace box (no connection needed)."""
    assert rig.ur5 is not None
    ur5 = rig.ur5
    if ur5.reference_pose is None:
        return DeviceCheck(
            "calibration", False, "no reference pose: run `pianobot rig calibrate RIGFILE`"
        )
    outside = [
        axis for axis, v, lo, hi in zip("xyz", ur5.reference_pose[:3], ur5.workspace_min_m,
                                        ur5.workspace_max_m, strict=True)
        if not lo <= v <= hi
    ]
    details = {"reference_pose": list(ur5.reference_pose), "calibrated_utc": ur5.calibrated_utc,
               "reference_note": ur5.reference_note}
    if outside:
        return DeviceCheck("calibration", False,
                           f"reference pose is outside the workspace box on {', '.join(outside)}",
                           details)
    return DeviceCheck("calibration", True,
                       f"reference note {ur5.reference_note}, calibrated {ur5.calibrated_utc}",
                       details)


def check_vacuum(rig: RigSpec, io_factory: Any = None, receive_factory: Any = None) -> DeviceCheck:
    """The regulator's signal and span, its I/O link and, if wired, its monitor reading."""
    vac = rig.vacuum
    if vac.mode == "manual":
        return DeviceCheck("vacuum", True, "manual: the operator sets the regulator when asked",
                           {"mode": "manual"})
    if vac.mode == "sim":
        return DeviceCheck("vacuum", True, "no regulator (levels are recorded, not driven)",
                           {"mode": "sim"})
    assert rig.ur5 is not None and vac.regulator is not None
    ur5, regulator = rig.ur5, vac.regulator
    command = command_span(regulator)
    _disconnect(open_io(ur5.host, ur5.connect_timeout_s, io_factory))
    details: dict[str, Any] = {
        "mode": "ur-analog", "output_channel": regulator.output_channel,
        "signal": regulator.signal, "signal_span": list(regulator.signal_span),
        "kpa_span": list(regulator.kpa_span),
    }
    summary = (f"RTDE I/O reachable; regulator on analog output {regulator.output_channel} "
               f"({regulator.signal} domain): {command.text()}")
    if vac.monitor is not None:
        monitor = monitor_span(vac.monitor, regulator)
        # -1: ur_rtde picks the rate from the controller version (a reading needs no more).
        receive = open_receive(ur5.host, -1.0, ur5.connect_timeout_s, receive_factory)
        try:
            value = float(getattr(receive, f"getStandardAnalogInput{vac.monitor.input_channel}")())
        finally:
            _disconnect(receive)
        kpa = monitor.kpa_for(value)
        details.update(monitor_channel=vac.monitor.input_channel, monitor=monitor.text(),
                       monitor_value=value, monitor_kpa=round(kpa, 2))
        summary += (f"; monitor on analog input {vac.monitor.input_channel} ({monitor.text()}) "
                    f"reads {value:.2f} {monitor.unit} = {kpa:.1f} kPa")
    else:
        summary += "; no monitor: levels are not read back"
    return DeviceCheck("vacuum", True, summary, details)


def check_midi(rig: RigSpec, backend_factory: Any = None) -> DeviceCheck:
    """The piano's MIDI port: found by its pattern and opened."""
    assert rig.midi is not None
    keyboard = MidiKeyboard(rig.midi.port, rig.midi.api, clock=WallClock(),
                            backend_factory=backend_factory or mido_backend)
    keyboard.start()
    info = keyboard.describe()
    keyboard.close()
    return DeviceCheck("midi", True, f"{info['api']} port {info['port']!r}",
                       {"api": info["api"], "port": info["port"]})


def _run(name: str, check: Callable[[], DeviceCheck], results: dict[str, DeviceCheck]) -> None:
    try:
        results[name] = check()
    except RigError as exc:
        results[name] = DeviceCheck(name, False, str(exc))
    except Exception as exc:  # a device check reports, it does not crash the command
        results[name] = DeviceCheck(name, False, f"{type(exc).__name__}: {exc}")


def check_rig(
    rig: RigSpec,
    *,
    receive_factory: Any = None,
    io_factory: Any = None,
    dashboard_factory: Any = None,
    midi_backend: Any = None,
) -> RigCheck:
    """Check every device of a lab rig concurrently; each answers within its connect timeout.

    The factories replace the vendor classes (tests pass fakes); None means the real SDK.
    """
    if rig.kind != "ur5" or rig.ur5 is None or rig.midi is None:
        raise ValueError("rig check needs a lab rig (kind: ur5) with ur5: and midi: sections")
    checks: dict[str, Callable[[], DeviceCheck]] = {
        "arm": lambda: check_arm(rig, receive_factory, dashboard_factory),
        "dashboard": lambda: check_dashboard(rig, dashboard_factory),
        "calibration": lambda: check_calibration(rig),
        "vacuum": lambda: check_vacuum(rig, io_factory, receive_factory),
        "midi": lambda: check_midi(rig, midi_backend),
    }
    results: dict[str, DeviceCheck] = {}
    threads = [
        threading.Thread(target=_run, args=(name, check, results), daemon=True,
                         name=f"rig-check-{name}")
        for name, check in checks.items()
    ]
    for thread in threads:
        thread.start()
    wait_s = rig.ur5.connect_timeout_s + GRACE_S
    deadline_s = time.monotonic() + wait_s  # the checks run in parallel: one wait for all
    for thread in threads:
        thread.join(timeout=max(0.0, deadline_s - time.monotonic()))
    devices = tuple(
        results.get(name) or DeviceCheck(name, False, f"no answer within {wait_s:g} s")
        for name in checks
    )
    return RigCheck(host=rig.ur5.host, devices=devices)
