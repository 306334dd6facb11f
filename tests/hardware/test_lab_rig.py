"""Real-hardware checks of the UR5 lab rig. Off by default: run with

    PIANOBOT_RIG=path/to/rig.yaml pytest -m hardware tests/hardware

Tests that move the arm also need PIANOBOT_HARDWARE_MOVE=1 and a calibrated rig file; they press
the reference key once, gently, inside the soft finger's envelope.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from pianobot.physics.trajectory import Press
from pianobot.rig.check import check_rig
from pianobot.rig.lab import LabDevices, open_lab_devices
from pianobot.spec import load_rig
from pianobot.spec.rig import RigSpec

pytestmark = pytest.mark.hardware

GENTLE_PRESS = Press(
    distance_m=0.01, depth_m=0.012, down_velocity_mps=0.02, up_velocity_mps=0.05,
    acceleration_mps2=0.5, hold_s=0.2,
)


@pytest.fixture(scope="module")
def rig() -> RigSpec:
    path = os.environ.get("PIANOBOT_RIG")
    if not path:
        pytest.skip("set PIANOBOT_RIG to a lab rig file")
    spec = load_rig(Path(path))
    if spec.kind != "ur5":
        pytest.skip("PIANOBOT_RIG is not a lab rig (kind: ur5)")
    return spec


@pytest.fixture()
def devices(rig: RigSpec) -> Iterator[LabDevices]:
    if os.environ.get("PIANOBOT_HARDWARE_MOVE") != "1":
        pytest.skip("set PIANOBOT_HARDWARE_MOVE=1 to let the test move the arm")
    lab = open_lab_devices(rig)
    try:
        lab.arm.connect()
        yield lab
    finally:
        lab.arm.make_safe()
        lab.vacuum.vent()
        lab.keyboard.close()
        lab.arm.close()


def test_every_device_answers(rig: RigSpec) -> None:
    report = check_rig(rig)
    assert report.ok, "; ".join(f"{d.device}: {d.summary}" for d in report.failures)


def test_one_gentle_press_on_the_reference_key(rig: RigSpec, devices: LabDevices) -> None:
    assert rig.ur5 is not None
    note = rig.ur5.reference_note
    devices.arm.move_to_key(note, GENTLE_PRESS.distance_m)
    record = devices.arm.press(GENTLE_PRESS, note)
    devices.clock.sleep(0.5)
    events = devices.keyboard.events_between(record.t_start_s, devices.clock.now())
    assert record.arm is not None and record.arm.x0_m is not None
    travel_m = GENTLE_PRESS.distance_m + GENTLE_PRESS.depth_m
    assert record.arm.x0_m.max() == pytest.approx(travel_m, abs=0.001)
    assert any(e.type == "note_on" and e.note == note for e in events), events
