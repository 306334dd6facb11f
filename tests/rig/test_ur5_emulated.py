"""UR5Arm with the real ur_rtde modules against the emulated controller (tests/hardware_emulator).

Each test here failed before the semantics it names were fixed (see the issue-14 note):
the RTDE rate asked of a CB3, the slider read as the trajectory limiter (no warning, a slow
press taken for a stall), a pause and a pendant stop answered with `reconnect()`, the
deprecated progress call, and trace samples whose pose could come from another cycle.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from emulated_lab import (
    HOVER_POSE,
    REFERENCE_POSE,
    SMC_ITV2090,
    SMC_MONITOR,
    lab_rig,
    ur5_config,
)
from fake_midi import FakeMidiBackend
from hardware_emulator import CB3, ESERIES, VacuumRegulator
from hardware_emulator.fixtures import EmulatorFactory

from pianobot.physics.approach import ApproachSettings, fast_press
from pianobot.physics.trajectory import Press, contact_speed_mps, move_profile
from pianobot.rig.check import check_rig
from pianobot.rig.clock import WallClock
from pianobot.rig.errors import ConnectionLost, DeviceUnavailable, RigError, SafetyStop
from pianobot.rig.lab import command_span, monitor_span
from pianobot.rig.ur5 import UR5Arm
from pianobot.rig.ur5_link import RECEIVE_VARIABLES
from pianobot.rig.ur5_session import close_link
from pianobot.rig.vacuum import AnalogVacuum
from pianobot.spec.rig import RigSpec

EXPERIMENTS = Path(__file__).resolve().parents[2] / "experiments"
NOTE = 59
PRESS = Press(distance_m=0.005, depth_m=0.015, down_velocity_mps=0.04, up_velocity_mps=0.1,
              acceleration_mps2=1.0, hold_s=0.05)
MOVEL = 3


def connect(host: str, **config: Any) -> UR5Arm:
    return UR5Arm.connect_to(ur5_config(host, **config), clock=WallClock())


@contextmanager
def hovering(ur_emulator: EmulatorFactory, **controller: Any) -> Iterator[tuple[Any, UR5Arm]]:
    """An emulated UR and pianobot's arm on it, hovering over the reference key."""
    ur = ur_emulator(start_pose=HOVER_POSE, **controller)
    arm = connect(ur.host)
    try:
        arm.move_to_key(NOTE, PRESS.distance_m)
        yield ur, arm
    finally:
        arm.close()


class Recording:
    """A transparent proxy that records which methods of the real SDK object are called."""

    def __init__(self, target: Any) -> None:
        self._target = target
        self.called: list[str] = []

    def __getattr__(self, name: str) -> Any:
        self.called.append(name)
        return getattr(self._target, name)


def controller_times(arm: UR5Arm, trace_t_s: np.ndarray) -> np.ndarray:
    assert arm.last_trace_offset_s is not None
    return np.round(trace_t_s - arm.last_trace_offset_s, 6)


@pytest.mark.parametrize(("generation", "rate_hz"), [(CB3, 125.0), (ESERIES, 500.0)])
def test_press_trace_has_one_cycle_per_sample_and_the_pose_of_that_cycle(
    ur_emulator: EmulatorFactory, generation: str, rate_hz: float,
) -> None:
    ur = ur_emulator(generation=generation, start_pose=HOVER_POSE)
    arm = connect(ur.host)
    try:
        # The rate follows the controller, as ur_rtde's own default does.
        assert arm.rate_hz == rate_hz and ur.output_frequencies() == [rate_hz, rate_hz]
        assert arm.describe()["controller"]["generation"] == ("CB3" if generation == CB3
                                                              else "e-Series")
        arm.move_to_key(NOTE, PRESS.distance_m)
        record = arm.press(PRESS, NOTE)
    finally:
        arm.close()
    trace = record.arm
    assert trace is not None and trace.x0_m is not None
    ctrl = controller_times(arm, trace.t_s)
    steps = np.diff(ctrl) * rate_hz
    assert np.all(steps > 0.5) and np.allclose(steps, np.round(steps), atol=1e-3)  # whole cycles
    assert len(ctrl) >= 20  # how many of the cycles a busy host reads in time varies
    truth = {round(t, 6): pose[2] for t, pose in ur.truth_between(ctrl[0] - 1, ctrl[-1] + 1)}
    hover_z = REFERENCE_POSE[2] + PRESS.distance_m
    for t, x0 in zip(ctrl, trace.x0_m, strict=True):  # the pose read is the cycle's own
        assert hover_z - x0 == truth[t]
    # And it is UR's trapezoid, checked against pianobot's own profile (written apart).
    travel = PRESS.distance_m + PRESS.depth_m
    profile = move_profile(travel, PRESS.down_velocity_mps, PRESS.acceleration_mps2)
    first_moving = ctrl[np.flatnonzero(trace.x0_m > 1e-9)[0]]
    t0 = max(t for t, z in truth.items() if t < first_moving and z == hover_z)  # last at rest
    down = (ctrl - t0 <= profile.duration_s) & (ctrl >= t0)
    expected, _ = profile.sample(ctrl[down] - t0)
    assert np.max(np.abs(trace.x0_m[down] - expected)) < 1e-6


def test_a_rate_the_rig_file_sets_is_used_unless_the_controller_cannot(
    ur_emulator: EmulatorFactory,
) -> None:
    ur = ur_emulator(generation=CB3, start_pose=HOVER_POSE)
    arm = connect(ur.host, frequency_hz=500.0)
    try:
        assert arm.rate_hz == 125.0 and "125 Hz" in " ".join(arm.warnings)
    finally:
        arm.close()
    eseries = ur_emulator(generation=ESERIES, start_pose=HOVER_POSE)
    arm = connect(eseries.host, frequency_hz=250.0)
    arm.close()
    assert eseries.output_frequencies() == [250.0, 250.0]


def test_a_slider_at_30_percent_is_warned_before_motion_and_is_no_stall(
    ur_emulator: EmulatorFactory,
) -> None:
    ur = ur_emulator(speed_slider=0.3, start_pose=HOVER_POSE)
    arm = connect(ur.host)
    try:
        assert MOVEL not in ur.get("commands")  # connected, nothing moved yet ...
        warning = " ".join(arm.warnings)  # ... and the warning is already there
        assert "speed slider is at 30 %" in warning and "9 %" in warning
        arm.move_to_key(NOTE, 0.01)
        # 30 mm at 0.03 m/s: 1.03 s nominal, 3.4 s at 30 % — past the nominal time + 2 s
        # that counted as a stall when the limiter's scaling (1.0) was read as the slider.
        slow = Press(0.01, 0.02, 0.03, 0.1, 1.0, 0.0)
        t0 = time.monotonic()
        record = arm.press(slow, NOTE)
        assert time.monotonic() - t0 > 3.0
    finally:
        arm.close()
    assert record.arm is not None and record.arm.x0_m is not None
    # The press went to full depth. Its bottom is one instant (no hold), and a loaded host
    # misses cycles (gaps in the trace), so the deepest sample may be up to ~30 ms before it:
    # 0.5 * (1.0 m/s^2 * 0.3^2) * 0.033^2 = 5e-5 m. A stopped or stalled press is mm short.
    assert record.arm.x0_m.max() == pytest.approx(0.03, abs=5e-5)
    assert any("speed scaling fell to 0.30" in w for w in record.warnings)


def test_a_program_paused_mid_press_stops_the_run_and_is_not_uploaded_over(
    ur_emulator: EmulatorFactory,
) -> None:
    with hovering(ur_emulator) as (ur, arm):
        connected = ur.counts()
        ur.fail_on_move(1, "pause", fraction=0.5)
        with pytest.raises(SafetyStop, match="paused"):
            arm.press(PRESS, NOTE)
        with pytest.raises(SafetyStop, match="paused"):
            arm.connect()  # the runner's retry path: it must not take the arm back
        assert ur.paused and ur.counts() == connected  # no new script, no reconnect


def test_a_program_paused_before_the_run_is_refused_before_taking_the_arm(
    ur_emulator: EmulatorFactory,
) -> None:
    import rtde_control

    ur = ur_emulator(start_pose=HOVER_POSE)
    someone = rtde_control.RTDEControlInterface(ur.host)  # someone's program, then paused
    ur.pause()
    assert ur.wait_until(lambda u: u.paused)
    someone.disconnect()
    with pytest.raises(DeviceUnavailable, match="paused"):
        connect(ur.host)
    assert ur.counts()["programs"] == 1  # ur_rtde's script was not uploaded over it
    ur.stop_program()


def test_a_script_stopped_at_the_pendant_is_reuploaded_not_reconnected(
    ur_emulator: EmulatorFactory,
) -> None:
    with hovering(ur_emulator) as (ur, arm):
        ur.stop_program()  # the links stay up
        with pytest.raises(ConnectionLost, match="control script not running"):
            arm.press(PRESS, NOTE)
        before = ur.counts()
        arm.connect()  # the runner's retry path
        after = ur.counts()
        assert after["programs"] == before["programs"] + 1  # re-uploaded ...
        assert after["connections"] == before["connections"]  # ... over the same links
        arm.move_to_key(NOTE, PRESS.distance_m)
        record = arm.press(PRESS, NOTE)
    assert record.arm is not None and record.arm.x0_m is not None
    assert record.arm.x0_m.max() == pytest.approx(PRESS.distance_m + PRESS.depth_m, abs=1e-6)


def test_a_link_dropped_mid_press_is_recovered_by_reconnecting(
    ur_emulator: EmulatorFactory,
) -> None:
    with hovering(ur_emulator) as (ur, arm):
        ur.fail_on_move(1, "drop_links", fraction=0.5, outage_s=0.3)
        with pytest.raises(ConnectionLost):
            arm.press(PRESS, NOTE)
        time.sleep(0.5)  # the runner's backoff
        arm.connect()
        arm.move_to_key(NOTE, PRESS.distance_m)
        record = arm.press(PRESS, NOTE)
    assert record.arm is not None and record.arm.x0_m is not None
    assert record.arm.x0_m.max() == pytest.approx(PRESS.distance_m + PRESS.depth_m, abs=1e-6)


def test_a_protective_stop_mid_press_stops_everything(ur_emulator: EmulatorFactory) -> None:
    with hovering(ur_emulator) as (ur, arm):
        moves_before = ur.get("commands").count(MOVEL)
        ur.fail_on_move(1, "protective_stop", fraction=0.4)
        with pytest.raises(SafetyStop, match="protective stopped"):
            arm.press(PRESS, NOTE)
        with pytest.raises(SafetyStop):
            arm.connect()
        assert ur.get("commands").count(MOVEL) == moves_before + 1  # nothing after the stop


def test_the_end_of_a_move_is_read_with_the_extended_progress_call(
    ur_emulator: EmulatorFactory,
) -> None:
    ur = ur_emulator(start_pose=HOVER_POSE)
    arm = connect(ur.host)
    recording = Recording(arm.control)
    arm.links.control = recording
    try:
        arm.move_to_key(NOTE, PRESS.distance_m)
        arm.press(PRESS, NOTE)
    finally:
        arm.close()
    assert "getAsyncOperationProgressEx" in recording.called
    assert "getAsyncOperationProgress" not in recording.called  # deprecated in ur_rtde 1.6
    assert math.isfinite(arm.rate_hz)


def test_a_two_segment_press_meets_the_key_as_the_spec_press_does(
    ur_emulator: EmulatorFactory,
) -> None:
    """Fast approach, the spec's move, the spec's move up, fast retract: four moveLs, and at
    contact the arm has the speed of the spec's single move."""
    spec = Press(distance_m=0.03, depth_m=0.01, down_velocity_mps=0.05, up_velocity_mps=0.05,
                 acceleration_mps2=1.0, hold_s=0.05)
    fast = fast_press(spec, ApproachSettings(velocity_mps=0.25, acceleration_mps2=2.0,
                                             clearance_m=0.005, settle_s=0.1))
    assert fast.approach_m > 0.01 and fast.retract_m > 0.01
    ur = ur_emulator(start_pose=HOVER_POSE)
    arm = connect(ur.host)
    try:
        arm.move_to_key(NOTE, fast.distance_m)
        before = ur.get("commands").count(MOVEL)
        record = arm.press(fast, NOTE)
    finally:
        arm.close()
    assert ur.get("commands").count(MOVEL) - before == 4
    assert record.arm is not None and record.arm.x0_m is not None
    ctrl = controller_times(arm, record.arm.t_s)
    truth = ur.truth_between(ctrl[0] - 1, ctrl[-1] + 1)
    t = np.array([ts for ts, _ in truth])
    z = np.array([pose[2] for _, pose in truth])
    touching = np.flatnonzero(z <= REFERENCE_POSE[2])[0]  # the first cycle at the key surface
    speed = (z[touching - 1] - z[touching]) / (t[touching] - t[touching - 1])
    assert speed == pytest.approx(contact_speed_mps(spec), rel=0.05)
    assert record.arm.x0_m.max() == pytest.approx(spec.distance_m + spec.depth_m, abs=1e-6)


def regulated(ur: Any, vacuum: dict[str, Any]) -> AnalogVacuum:
    """The rig file's vacuum section, built as `open_lab_devices` does, on real ur_rtde links."""
    import rtde_io
    import rtde_receive

    spec = RigSpec.model_validate(lab_rig(ur.host, vacuum=vacuum)).vacuum
    assert spec.regulator is not None
    receive = rtde_receive.RTDEReceiveInterface(ur.host, -1.0, RECEIVE_VARIABLES)
    return AnalogVacuum(
        command_span(spec.regulator), io=rtde_io.RTDEIOInterface(ur.host), clock=WallClock(),
        output_channel=spec.regulator.output_channel, receive=receive,
        monitor=None if spec.monitor is None else monitor_span(spec.monitor, spec.regulator),
        input_channel=None if spec.monitor is None else spec.monitor.input_channel,
        settle_timeout_s=3.0, tolerance_kpa=1.0,
    )


def test_the_regulators_declared_signal_and_span_put_the_finger_at_the_level(
    ur_emulator: EmulatorFactory,
) -> None:
    # An SMC ITV2090 (0 to -80 kPa over 0-10 V, 1-5 V monitor) as in experiments/rigs/ur5-lab.yaml.
    ur = ur_emulator()
    vacuum = regulated(ur, {"mode": "ur-analog", "regulator": SMC_ITV2090, "monitor": SMC_MONITOR})
    assert vacuum.set_kpa(-40.0) == pytest.approx(-40.0, abs=1.0)
    assert ur.regulator_kpa() == pytest.approx(-40.0, abs=1.0)  # the regulator's own pressure
    vacuum.vent()
    assert ur.wait_until(lambda u: abs(u.regulator_kpa() or 0.0) < 1.0)
    close_link(vacuum._io)


def test_a_current_loop_regulator_is_driven_in_the_current_domain(
    ur_emulator: EmulatorFactory,
) -> None:
    # A 4-20 mA regulator on analog output 1: ur_rtde's setAnalogOutputCurrent.
    current = VacuumRegulator(output_channel=1, signal="current", signal_span=(4.0, 20.0),
                              kpa_span=(0.0, -100.0), monitor_channel=0,
                              monitor_signal="voltage", monitor_span=(0.0, 10.0))
    ur = ur_emulator(regulator=current)
    declared = {"output_channel": 1, "signal": "current", "signal_span": [4.0, 20.0],
                "kpa_span": [0.0, -100.0]}
    monitor = {"input_channel": 0, "signal": "voltage", "signal_span": [0.0, 10.0]}
    vacuum = regulated(ur, {"mode": "ur-analog", "regulator": declared, "monitor": monitor})
    assert vacuum.set_kpa(-60.0) == pytest.approx(-60.0, abs=1.0)
    assert ur.get("analog_domain")[1] == "current"
    close_link(vacuum._io)
    # Declared as voltage, the same regulator gets no valid signal: the read-back says so.
    wrong = regulated(ur, {"mode": "ur-analog", "monitor": monitor,
                           "regulator": {**declared, "signal": "voltage",
                                         "signal_span": [0.0, 10.0]}})
    with pytest.raises(RigError, match=r"did not settle at -30 .*0-10 V = 0 to -100 kPa"):
        wrong.set_kpa(-30.0)
    close_link(wrong._io)


@pytest.mark.parametrize(("generation", "expected"), [
    (CB3, "CB3 (PolyScope 3.15.7.106331), RTDE 125 Hz (CB3 default, streaming at 125 Hz)"),
    (ESERIES, "e-Series (PolyScope 5.11.1.108318), RTDE 500 Hz (e-Series default, streaming at "
              "500 Hz)"),
])
def test_rig_check_reports_what_the_controller_says(
    ur_emulator: EmulatorFactory, generation: str, expected: str,
) -> None:
    ur = ur_emulator(generation=generation, speed_slider=0.5)
    example = yaml.safe_load((EXPERIMENTS / "rigs" / "ur5-lab.yaml").read_text())
    example["ur5"]["host"] = ur.host
    report = check_rig(RigSpec.model_validate(example),
                       midi_backend=lambda api: FakeMidiBackend(["Kawai ES8 MIDI 1"]))
    by_name = {d.device: d for d in report.devices}
    arm = by_name["arm"]
    assert arm.ok and expected in arm.summary, arm.summary
    assert "speed slider 50 %" in arm.summary and "combined scaling 0.50" in arm.summary
    assert "warning: the teach pendant's speed slider is at 50 %" in arm.summary
    assert arm.details["program_state"] == "STOPPED" and arm.details["safety_status"] == ["normal"]
    vacuum = by_name["vacuum"]
    assert vacuum.ok and "voltage domain" in vacuum.summary
    assert "0-10 V = 0 to -80 kPa" in vacuum.summary and "reads 1.00 V = 0.0 kPa" in vacuum.summary
    assert by_name["dashboard"].ok and not by_name["calibration"].ok  # the example is uncalibrated
    assert MOVEL not in ur.get("commands") and ur.counts()["programs"] == 0  # nothing commanded
