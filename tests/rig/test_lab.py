"""The lab rig assembled from a rig file, on fakes of ur_rtde and of the MIDI backend."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial
from typing import Any

import pytest
from fake_midi import FakeMidiBackend
from fake_rtde import FakeClock, FakeController, sdk_factories

from pianobot.physics.trajectory import Press
from pianobot.rig import lab, open_rig
from pianobot.rig.errors import DeviceUnavailable
from pianobot.rig.lab import SdkFactories, open_lab_devices
from pianobot.rig.midi import MidiKeyboard
from pianobot.rig.ur5 import UR5Arm
from pianobot.rig.vacuum import AnalogVacuum, CommandedVacuum, ManualVacuum
from pianobot.spec.rig import RigSpec

PIANO_PORT = "Kawai ES8:Kawai ES8 MIDI 1 20:0"
REFERENCE_POSE = [-0.5, -0.1, 0.1, 0.0, math.pi, 0.0]


# The fake regulator's monitor repeats its command: same span both ways.
REGULATOR = {"output_channel": 1, "signal": "voltage", "signal_span": [0, 10], "kpa_span": [0, -100]}
MONITOR = {"input_channel": 0, "signal": "voltage", "signal_span": [0, 10]}


def lab_rig(**vacuum: Any) -> RigSpec:
    return RigSpec.model_validate({
        "kind": "ur5",
        "ur5": {
            "host": "192.0.2.10",
            "workspace_min_m": [-0.75, -0.35, 0.02],
            "workspace_max_m": [-0.30, 0.10, 0.30],
            "reference_pose": REFERENCE_POSE,
            "calibrated_utc": "2026-01-01T00:00:00Z",
        },
        "vacuum": {"mode": "ur-analog", "regulator": REGULATOR, "monitor": MONITOR, **vacuum},
        "midi": {"api": "ALSA", "port": "ES8"},
        "keyboard": {"offsets_m": {60: 0.0005}},
        "settle_s": {"after_vacuum_change_s": 1.0, "between_presses_s": 0.3},
    })


@dataclass
class Lab:
    robot: FakeController
    midi: FakeMidiBackend
    factories: SdkFactories


@pytest.fixture()
def fake_lab() -> Lab:
    robot = FakeController(clock=FakeClock(), pose=[-0.5, -0.1, 0.2, 0.0, math.pi, 0.0])
    midi = FakeMidiBackend([PIANO_PORT, "Midi Through:Midi Through Port-0 14:0"])
    fakes = sdk_factories(robot)
    factories = SdkFactories(
        receive=fakes["receive"], control=fakes["control"], io=fakes["io"],
        midi_backend=lambda api: midi, dashboard=fakes["dashboard"],
    )
    return Lab(robot, midi, factories)


def test_open_lab_devices_builds_every_device(fake_lab: Lab) -> None:
    arm, vacuum, keyboard, mocap, clock = open_lab_devices(
        lab_rig(), clock=fake_lab.robot.clock, factories=fake_lab.factories
    )
    assert isinstance(arm, UR5Arm) and isinstance(vacuum, AnalogVacuum)
    assert isinstance(keyboard, MidiKeyboard) and mocap is None
    assert keyboard.describe()["port"] == PIANO_PORT
    assert arm.geometry.offsets == {60: 0.0005}
    assert arm.key_pose(60)[0] == pytest.approx(REFERENCE_POSE[0] + 0.0235 + 0.0005)
    assert vacuum.set_kpa(-30.0) == pytest.approx(-30.0, abs=2.0)  # read back on input 0
    assert fake_lab.robot.analog_out[1] == pytest.approx(0.3)
    assert arm.describe()["controller"]["polyscope_version"] == "5.11.1.108318"


def test_midi_note_filter_from_the_rig_file(fake_lab: Lab) -> None:
    rig = lab_rig()
    assert rig.midi is not None
    rig = rig.model_copy(update={"midi": rig.midi.model_copy(update={"note": 57})})
    devices = open_lab_devices(rig, clock=fake_lab.robot.clock, factories=fake_lab.factories)
    fake_lab.midi.play("note_on", note=60, velocity=40)
    fake_lab.midi.play("note_on", note=57, velocity=50)
    events = devices.keyboard.events_between(0.0, 1.0)
    assert [(e.note, e.velocity) for e in events] == [(57, 50)]


@pytest.mark.parametrize(("mode", "kind"), [("manual", ManualVacuum), ("sim", CommandedVacuum)])
def test_vacuum_mode_picks_the_regulator(fake_lab: Lab, mode: str, kind: type) -> None:
    devices = open_lab_devices(lab_rig(mode=mode), clock=fake_lab.robot.clock,
                               factories=fake_lab.factories)
    assert isinstance(devices.vacuum, kind)
    assert all(interface != "io" for interface, _, _ in fake_lab.robot.calls)  # no RTDE I/O


def test_unreachable_arm_closes_the_midi_port_again(fake_lab: Lab) -> None:
    fake_lab.robot.listening = False
    with pytest.raises(DeviceUnavailable, match="192.0.2.10:(30004|29999)"):
        open_lab_devices(lab_rig(), clock=fake_lab.robot.clock, factories=fake_lab.factories)
    assert fake_lab.midi.ports and all(port.closed for port in fake_lab.midi.ports)


def test_wrong_midi_port_fails_before_the_arm_is_taken(fake_lab: Lab) -> None:
    rig = lab_rig()
    assert rig.midi is not None
    rig = rig.model_copy(update={"midi": rig.midi.model_copy(update={"port": "P-125"})})
    with pytest.raises(DeviceUnavailable, match="no MIDI input port matches 'P-125'"):
        open_lab_devices(rig, clock=fake_lab.robot.clock, factories=fake_lab.factories)
    assert fake_lab.robot.calls == []


@dataclass(frozen=True)
class Stroke:
    """A planned keystroke, as the station needs it."""

    trial_id: str
    index: int
    note: int
    vacuum_kpa: float
    distance_m: float

    def press(self) -> Press:
        return Press(self.distance_m, 0.012, 0.04, 0.1, 1.0, 0.05)


def test_keystroke_through_open_rig_on_the_fake_lab(
    fake_lab: Lab, monkeypatch: pytest.MonkeyPatch
) -> None:
    """C's open_rig + Station drive the UR5 backend; MIDI comes back by time window."""
    key_surface_z = REFERENCE_POSE[2]
    state = {"down": False}

    def piano(robot: FakeController) -> None:
        # The key sounds when the fingertip is 8 mm into it and releases near the top.
        z = robot.pose[2]
        if not state["down"] and z < key_surface_z - 0.008:
            state["down"] = True
            fake_lab.midi.play("note_on", note=57, velocity=70)
        elif state["down"] and z > key_surface_z - 0.002:
            state["down"] = False
            fake_lab.midi.play("note_on", note=57, velocity=0)

    fake_lab.robot.on_tick = piano
    monkeypatch.setattr(
        lab, "open_lab_devices",
        partial(open_lab_devices, clock=fake_lab.robot.clock, factories=fake_lab.factories),
    )
    with open_rig(lab_rig()) as rig:
        first = rig.keystroke(Stroke("t0", 0, 57, -20.0, 0.02))
        second = rig.keystroke(Stroke("t1", 1, 57, -20.0, 0.02))
    for result in (first, second):
        assert [(e.type, e.note) for e in result.midi] == [("note_on", 57), ("note_off", 57)]
        assert result.press.t_start_s < result.midi[0].t_s < result.midi[1].t_s
        assert result.vacuum_kpa_measured == pytest.approx(-20.0, abs=2.0)
        assert result.traces and result.traces[0].source == "arm"
    assert second.midi[0].t_s > first.midi[1].t_s
    # On exit the rig was made safe: vented and retracted above the keys.
    assert fake_lab.robot.analog_out[1] == 0.0
    assert fake_lab.robot.pose[2] >= key_surface_z + 0.05 - 1e-9
    assert fake_lab.robot.calls_to("stopScript")
