"""Real-hardware checks of the UR5 lab rig: run them once on the lab's own robot. Off by default:

    PIANOBOT_RIG=path/to/rig.yaml pytest -m hardware tests/hardware                  # moves nothing
    PIANOBOT_RIG=... PIANOBOT_HARDWARE_VACUUM=1 pytest -m hardware tests/hardware    # + the regulator
    PIANOBOT_RIG=... PIANOBOT_HARDWARE_MOVE=1 pytest -m hardware tests/hardware      # + gentle presses

The emulated controller (tests/hardware_emulator) proves pianobot against ur_rtde's protocol;
these settle what only the lab's controller can: that the stream runs at the rate pianobot chose
for its generation, that the pendant's slider is where the data needs it, that a pendant stop is
recovered by re-uploading the script and a pause is left alone, that the regulator's declared
signal and span put the finger at the commanded levels, and that a press's trace has one
controller cycle per sample. Dashboard commands need the e-Series pendant in Remote Control.
Tests that move the arm need a calibrated rig file; they press the reference key gently, inside
the soft finger's envelope.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pianobot.physics.approach import ApproachSettings, fast_press
from pianobot.physics.trajectory import Press
from pianobot.rig.check import check_arm, check_rig, measured_rate_hz
from pianobot.rig.errors import SafetyStop
from pianobot.rig.lab import LabDevices, open_lab_devices
from pianobot.rig.ur5_link import choose_rate, open_dashboard, open_receive, read_controller
from pianobot.rig.ur5_session import Links, close_link, open_links, reconnect
from pianobot.spec import load_rig
from pianobot.spec.rig import RigSpec

pytestmark = pytest.mark.hardware

GENTLE_PRESS = Press(
    distance_m=0.01, depth_m=0.012, down_velocity_mps=0.02, up_velocity_mps=0.05,
    acceleration_mps2=0.5, hold_s=0.2,
)


def _flag(name: str) -> None:
    if os.environ.get(name) != "1":
        pytest.skip(f"set {name}=1 to run this on the robot")


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
def dashboard(rig: RigSpec) -> Iterator[Any]:
    assert rig.ur5 is not None
    client = open_dashboard(rig.ur5.host, rig.ur5.connect_timeout_s)
    yield client
    client.disconnect()


@pytest.fixture()
def devices(rig: RigSpec) -> Iterator[LabDevices]:
    _flag("PIANOBOT_HARDWARE_MOVE")
    lab = open_lab_devices(rig)
    try:
        yield lab
    finally:
        lab.arm.make_safe()
        lab.vacuum.vent()
        lab.keyboard.close()
        lab.arm.close()


def test_every_device_answers(rig: RigSpec) -> None:
    report = check_rig(rig)
    assert report.ok, "; ".join(f"{d.device}: {d.summary}" for d in report.failures)


def test_the_stream_runs_at_the_rate_chosen_for_the_controller(rig: RigSpec, dashboard: Any) -> None:
    assert rig.ur5 is not None
    controller = read_controller(dashboard, rig.ur5.host)
    rate, _ = choose_rate(rig.ur5.frequency_hz, controller)
    receive = open_receive(rig.ur5.host, rate, rig.ur5.connect_timeout_s)
    try:
        measured = measured_rate_hz(receive, window_s=0.5)
    finally:
        receive.disconnect()
    assert measured == pytest.approx(rate, rel=0.01), f"{controller.generation}: {measured} Hz"


def test_the_speed_slider_and_limiter_are_at_100_percent(rig: RigSpec) -> None:
    arm = check_arm(rig)
    assert arm.details["speed_slider"] == pytest.approx(1.0), arm.summary
    if arm.details["program_state"] == "PLAYING":  # the limiter only scales a running program
        assert arm.details["speed_scaling"] == pytest.approx(1.0), arm.summary


@pytest.fixture()
def links(rig: RigSpec) -> Iterator[Links]:
    """ur_rtde's script running on the robot (no motion, no calibration needed)."""
    assert rig.ur5 is not None
    opened = open_links(rig.ur5)
    yield opened
    if opened.control.isProgramRunning():
        opened.control.stopScript()
    for link in (opened.control, opened.receive):
        close_link(link)
    opened.dashboard.disconnect()


def test_a_pendant_stop_is_recovered_by_reuploading_the_script(
    rig: RigSpec, dashboard: Any, links: Links,
) -> None:
    assert rig.ur5 is not None
    dashboard.stop()  # as the pendant's stop: the script ends, the links stay up
    time.sleep(0.5)
    assert not links.control.isProgramRunning() and links.control.isConnected()
    reconnect(links, None, rig.ur5.host)
    assert links.control.isProgramRunning() and links.receive.isConnected()


def test_a_paused_program_is_not_uploaded_over(rig: RigSpec, dashboard: Any, links: Links) -> None:
    assert rig.ur5 is not None
    dashboard.pause()
    time.sleep(0.5)
    with pytest.raises(SafetyStop, match="paused"):
        reconnect(links, None, rig.ur5.host)
    dashboard.play()
    time.sleep(0.5)
    assert links.control.isProgramRunning()


def test_the_regulator_reaches_each_level(rig: RigSpec) -> None:
    """Moves nothing; the finger stiffens. With a monitor the read-back must settle at each
    level; without one, compare the regulator's own display by eye at each pause."""
    _flag("PIANOBOT_HARDWARE_VACUUM")
    if rig.vacuum.mode != "ur-analog":
        pytest.skip("the rig's vacuum is not driven from the UR")
    lab = open_lab_devices(rig)
    try:
        for level in (-20.0, -40.0, -60.0):
            measured = lab.vacuum.set_kpa(level)
            assert measured == pytest.approx(level, abs=rig.vacuum.tolerance_kpa)
            lab.clock.sleep(3.0)
    finally:
        lab.vacuum.vent()
        lab.keyboard.close()
        lab.arm.close()


def _check_trace(arm: Any, record: Any, travel_m: float) -> None:
    assert record.arm is not None and record.arm.x0_m is not None
    assert record.arm.x0_m.max() == pytest.approx(travel_m, abs=0.001)
    steps = np.diff(record.arm.t_s) * arm.rate_hz  # one controller cycle per sample, or gaps
    assert np.allclose(steps, np.round(steps), atol=0.02) and np.all(steps > 0.5)
    assert len(steps) > 0.8 * (record.arm.t_s[-1] - record.arm.t_s[0]) * arm.rate_hz


def test_one_gentle_press_on_the_reference_key(rig: RigSpec, devices: LabDevices) -> None:
    assert rig.ur5 is not None
    note = rig.ur5.reference_note
    devices.arm.move_to_key(note, GENTLE_PRESS.distance_m)
    record = devices.arm.press(GENTLE_PRESS, note)
    devices.clock.sleep(0.5)
    events = devices.keyboard.events_between(record.t_start_s, devices.clock.now())
    _check_trace(devices.arm, record, GENTLE_PRESS.distance_m + GENTLE_PRESS.depth_m)
    assert any(e.type == "note_on" and e.note == note for e in events), events


def test_one_gentle_two_segment_press(rig: RigSpec, devices: LabDevices) -> None:
    assert rig.ur5 is not None
    note = rig.ur5.reference_note
    spec = Press(0.04, 0.012, 0.02, 0.05, 0.5, 0.2)
    press = fast_press(spec, ApproachSettings(velocity_mps=0.1, acceleration_mps2=0.5,
                                              clearance_m=0.01, settle_s=0.5))
    assert press.approach_m > 0
    devices.arm.move_to_key(note, press.distance_m)
    record = devices.arm.press(press, note)
    _check_trace(devices.arm, record, spec.distance_m + spec.depth_m)
