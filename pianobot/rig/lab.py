"""The UR5 lab's devices, built from a rig file (`kind: ur5`).

`open_lab_devices` opens the MIDI port first (no side effects, fails fast on a wrong port name),
then takes control of the arm, then the vacuum I/O; if anything fails, what was opened is
closed again. Vendor SDKs are imported inside the device modules, only when needed.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

from pianobot.physics.keyboard import KeyboardGeometry
from pianobot.rig.clock import WallClock
from pianobot.rig.errors import DeviceUnavailable, RigError
from pianobot.rig.midi import MidiKeyboard, mido_backend
from pianobot.rig.protocols import Arm, Clock, Keyboard, Mocap, Vacuum
from pianobot.rig.ur5 import DEFAULT_KEYBOARD_AXIS, UR5Arm
from pianobot.rig.ur5_link import open_io
from pianobot.rig.ur5_session import close_link
from pianobot.rig.vacuum import AnalogVacuum, CommandedVacuum, ManualVacuum, SignalSpan
from pianobot.spec.rig import RegulatorCommand, RegulatorMonitor, RigSpec


class LabDevices(NamedTuple):
    """The devices of the lab rig (unpacks as arm, vacuum, keyboard, mocap, clock)."""

    arm: Arm
    vacuum: Vacuum
    keyboard: Keyboard
    mocap: Mocap | None
    clock: Clock


class SdkFactories(NamedTuple):
    """Replacements for the vendor classes (tests pass fakes); None = the real SDK."""

    receive: Any = None
    control: Any = None
    io: Any = None
    midi_backend: Any = None
    dashboard: Any = None


def keyboard_geometry(rig_spec: RigSpec) -> KeyboardGeometry:
    """The keyboard geometry of a rig file, anchored at the arm's reference key."""
    reference = rig_spec.ur5.reference_note if rig_spec.ur5 is not None else 59
    try:
        return KeyboardGeometry(
            white_pitch_m=rig_spec.keyboard.white_key_pitch_m,
            reference_note=reference,
            offsets_m=tuple(rig_spec.keyboard.offsets_m.items()),
        )
    except ValueError as exc:
        raise DeviceUnavailable(f"keyboard geometry: {exc}") from exc


def keyboard_axis(rig_spec: RigSpec) -> Sequence[float]:
    """Bass → treble direction in the arm's base frame: the rig's `ur5.keyboard_axis` if the
    rig file has one, else base +x (the documented default)."""
    axis = getattr(rig_spec.ur5, "keyboard_axis", None)
    return DEFAULT_KEYBOARD_AXIS if axis is None else tuple(axis)


def open_lab_devices(
    rig_spec: RigSpec,
    *,
    clock: Clock | None = None,
    factories: SdkFactories = SdkFactories(),
) -> LabDevices:
    """Open the lab rig's arm, vacuum and MIDI input (mocap comes from Motive CSV imports).

    Raises DeviceUnavailable naming the device that cannot be reached.
    """
    if rig_spec.kind != "ur5" or rig_spec.ur5 is None or rig_spec.midi is None:
        raise DeviceUnavailable("lab devices need a rig file with kind: ur5, ur5: and midi:")
    ur5, midi, vac = rig_spec.ur5, rig_spec.midi, rig_spec.vacuum
    run_clock: Clock = clock if clock is not None else WallClock()
    opened: list[Any] = []
    try:
        keyboard = MidiKeyboard(
            midi.port, midi.api, clock=run_clock, note=midi.note,
            backend_factory=factories.midi_backend or mido_backend,
        )
        keyboard.start()
        opened.append(keyboard)
        io: Any = None
        if vac.mode == "ur-analog":
            io = open_io(ur5.host, ur5.connect_timeout_s, factories.io)
            opened.append(io)
        arm = UR5Arm.connect_to(
            ur5,
            clock=run_clock,
            receive_factory=factories.receive,
            control_factory=factories.control,
            dashboard_factory=factories.dashboard,
            io=io,
            geometry=keyboard_geometry(rig_spec),
            keyboard_axis=keyboard_axis(rig_spec),
            travel_velocity_mps=rig_spec.travel.velocity_mps,
            travel_acceleration_mps2=rig_spec.travel.acceleration_mps2,
        )
        opened.append(arm)
        vacuum: Vacuum
        if io is not None:
            assert vac.regulator is not None  # the rig file's validation guarantees it
            vacuum = AnalogVacuum(
                command_span(vac.regulator),
                io=io,
                receive=arm.receive,
                clock=run_clock,
                output_channel=vac.regulator.output_channel,
                monitor=None if vac.monitor is None else monitor_span(vac.monitor, vac.regulator),
                input_channel=None if vac.monitor is None else vac.monitor.input_channel,
                settle_timeout_s=vac.settle_timeout_s,
                tolerance_kpa=vac.tolerance_kpa,
            )
        elif vac.mode == "manual":
            vacuum = ManualVacuum()
        else:
            vacuum = CommandedVacuum()
    except (RigError, ValueError) as exc:
        for device in reversed(opened):
            _close(device)
        if isinstance(exc, RigError):
            raise
        raise DeviceUnavailable(str(exc)) from exc
    return LabDevices(arm=arm, vacuum=vacuum, keyboard=keyboard, mocap=None, clock=run_clock)


def command_span(regulator: RegulatorCommand) -> SignalSpan:
    """The regulator's command signal ↔ pressure map from the rig file."""
    return SignalSpan(regulator.signal, regulator.signal_span, regulator.kpa_span)


def monitor_span(monitor: RegulatorMonitor, regulator: RegulatorCommand) -> SignalSpan:
    """The monitor output's signal ↔ pressure map (the command's pressures unless given)."""
    return SignalSpan(monitor.signal, monitor.signal_span, monitor.kpa_span or regulator.kpa_span)


def _close(device: Any) -> None:
    close = getattr(device, "close", None)
    if close is None:  # a ur_rtde object
        close_link(device)
        return
    try:
        close()
    except Exception:  # closing after a failure must not hide that failure
        pass
