"""`pianobot rig check`: reach every device a lab rig file configures and report what it says.

Each device is checked in its own thread with the rig's short connect timeout, so a rig with
nothing on the network answers within a few seconds with one reason per device. Nothing is
commanded: the arm is read over RTDE receive only (the control interface would take the arm
over), the vacuum I/O is connected but no output is set.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from pianobot.rig.clock import WallClock
from pianobot.rig.errors import RigError
from pianobot.rig.midi import MidiKeyboard, mido_backend
from pianobot.rig.ur5_link import open_dashboard, open_io, open_receive, read_status
from pianobot.rig.vacuum import ANALOG_INPUT_FULL_SCALE_V, LinearCalibration
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


def check_arm(rig: RigSpec, factory: Any = None) -> DeviceCheck:
    """RTDE receive: robot mode, safety status, speed scaling, TCP pose."""
    assert rig.ur5 is not None
    ur5 = rig.ur5
    receive = open_receive(ur5.host, ur5.frequency_hz, ur5.connect_timeout_s, factory)
    try:
        status = read_status(receive)
        pose = [round(float(v), 5) for v in receive.getActualTCPPose()]
    finally:
        _disconnect(receive)
    details = {**status.to_dict(), "tcp_pose": pose}
    summary = f"{ur5.host}: {status.text()}"
    if status.stopped:
        return DeviceCheck("arm", False, f"{summary}; clear the stop on the teach pendant", details)
    if status.robot_mode is not None and status.robot_mode != 7:
        return DeviceCheck("arm", False, f"{summary}; power on and release the brakes", details)
    if status.speed_scaling is not None and status.speed_scaling < ur5.max_speed_scaling_warning:
        summary += " (speed slider below 100 %: every move will be stretched)"
    return DeviceCheck("arm", True, summary, details)


def check_dashboard(rig: RigSpec, factory: Any = None) -> DeviceCheck:
    """Dashboard server: PolyScope version, model, serial number, safety status."""
    assert rig.ur5 is not None
    client = open_dashboard(rig.ur5.host, rig.ur5.connect_timeout_s, factory)
    details: dict[str, Any] = {}
    try:
        for key, method in (
            ("polyscope_version", "polyscopeVersion"), ("robot_model", "getRobotModel"),
            ("serial_number", "getSerialNumber"), ("robot_mode", "robotmode"),
            ("safety_status", "safetystatus"), ("remote_control", "isInRemoteControl"),
        ):
            try:
                details[key] = getattr(client, method)()
            except Exception:  # CB3 controllers lack some queries: report what answers
                details[key] = None
    finally:
        _disconnect(client)
    version = details.get("polyscope_version") or "unknown PolyScope version"
    summary = f"{version}, {details.get('robot_model') or 'unknown model'}"
    if details.get("safety_status"):
        summary += f", {details['safety_status']}"
    if details.get("remote_control") is False:
        summary += " (not in remote control: ur_rtde cannot take the arm)"
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
    """The regulator's I/O link and, if wired, its read-back."""
    vac = rig.vacuum
    if vac.mode == "manual":
        return DeviceCheck("vacuum", True, "manual: the operator sets the regulator when asked",
                           {"mode": "manual"})
    if vac.mode == "sim":
        return DeviceCheck("vacuum", True, "no regulator (levels are recorded, not driven)",
                           {"mode": "sim"})
    assert rig.ur5 is not None
    ur5 = rig.ur5
    _disconnect(open_io(ur5.host, ur5.connect_timeout_s, io_factory))
    details: dict[str, Any] = {"mode": "ur-analog", "output_channel": vac.output_channel,
                               "input_channel": vac.input_channel}
    summary = f"RTDE I/O reachable, setpoint on analog output {vac.output_channel}"
    if vac.input_channel is not None:
        receive = open_receive(ur5.host, ur5.frequency_hz, ur5.connect_timeout_s, receive_factory)
        try:
            volts = float(getattr(receive, f"getStandardAnalogInput{vac.input_channel}")())
        finally:
            _disconnect(receive)
        calibration = LinearCalibration(vac.kpa_at_ratio_0, vac.kpa_at_ratio_1)
        kpa = calibration.kpa(volts / ANALOG_INPUT_FULL_SCALE_V)
        details.update(read_back_v=volts, read_back_kpa=round(kpa, 2))
        summary += f"; read-back {kpa:.1f} kPa ({volts:.2f} V on input {vac.input_channel})"
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
        "arm": lambda: check_arm(rig, receive_factory),
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
