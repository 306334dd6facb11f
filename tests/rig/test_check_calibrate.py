"""`rig check` device reports and `rig calibrate` teach-mode calibration, on fakes."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import pytest
from fake_midi import FakeMidiBackend
from fake_rtde import FakeClock, FakeController, sdk_factories

from pianobot.rig.calibrate import calibrate_reference_pose, note_name
from pianobot.rig.check import check_rig, measured_rate_hz
from pianobot.rig.errors import DeviceUnavailable, RigError
from pianobot.spec import load_rig
from pianobot.spec.rig import RigSpec

RIG_YAML = """\
# lab rig for tests
kind: ur5
ur5:
  host: 192.0.2.10
  connect_timeout_s: 0.5
  workspace_min_m: [-0.75, -0.35, 0.02]
  workspace_max_m: [-0.30, 0.10, 0.30]
  reference_pose: null   # written by calibrate
  reference_note: 59
  calibrated_utc: null
vacuum:
  mode: ur-analog
  regulator: {output_channel: 1, signal: voltage, signal_span: [0, 10], kpa_span: [0, -100]}
  monitor: {input_channel: 0, signal: voltage, signal_span: [0, 10]}
midi:
  api: JACK
  port: ES8
"""
TAUGHT_POSE = [-0.52, -0.08, 0.11, 0.01, 3.12, -0.02]


@pytest.fixture()
def robot() -> FakeController:
    return FakeController(clock=FakeClock(), pose=list(TAUGHT_POSE))


@pytest.fixture()
def rig_file(tmp_path: Path) -> Path:
    path = tmp_path / "lab.yaml"
    path.write_text(RIG_YAML)
    return path


def fakes(robot: FakeController, ports: list[str] | None = None) -> dict[str, object]:
    midi = FakeMidiBackend(ports if ports is not None else ["Kawai ES8:Kawai ES8 MIDI 1 20:0"])
    sdk = sdk_factories(robot)
    return {
        "receive_factory": sdk["receive"],
        "io_factory": sdk["io"],
        "dashboard_factory": sdk["dashboard"],
        "midi_backend": lambda api: midi,
    }


def test_check_reports_every_device(robot: FakeController, rig_file: Path) -> None:
    robot.set_analog(1, 0.4)  # the regulator holds -40 kPa
    robot.clock.sleep(10.0)
    report = check_rig(load_rig(rig_file), **fakes(robot))  # type: ignore[arg-type]
    by_name = {d.device: d for d in report.devices}
    assert list(by_name) == ["arm", "dashboard", "calibration", "vacuum", "midi"]
    assert by_name["arm"].ok and "robot mode RUNNING" in by_name["arm"].summary
    assert "e-Series (PolyScope 5.11.1.108318), RTDE 500 Hz" in by_name["arm"].summary
    assert by_name["arm"].details["tcp_pose"] == pytest.approx(TAUGHT_POSE)
    assert by_name["arm"].details["speed_slider"] == 1.0
    assert by_name["dashboard"].details["polyscope_version"] == "5.11.1.108318"
    assert not by_name["calibration"].ok and "rig calibrate" in by_name["calibration"].summary
    assert by_name["vacuum"].details["monitor_kpa"] == pytest.approx(-40.0, abs=0.1)
    assert "0-10 V = 0 to -100 kPa" in by_name["vacuum"].summary
    assert by_name["midi"].details["port"] == "Kawai ES8:Kawai ES8 MIDI 1 20:0"
    assert [d.device for d in report.failures] == ["calibration"]
    assert not any(name == "moveL" for _, name, _ in robot.calls)  # a check moves nothing


def test_check_flags_a_protective_stop_and_slow_speed_slider(
    robot: FakeController, rig_file: Path
) -> None:
    robot.protective_stopped = True
    report = check_rig(load_rig(rig_file), **fakes(robot))  # type: ignore[arg-type]
    arm = report.devices[0]
    assert not arm.ok and "protective stopped" in arm.summary and "teach pendant" in arm.summary
    robot.protective_stopped = False
    robot.speed_slider = 0.3
    arm = check_rig(load_rig(rig_file), **fakes(robot)).devices[0]  # type: ignore[arg-type]
    assert arm.ok and "speed slider 30 %" in arm.summary and "warning" in arm.summary
    assert arm.details["speed_scaling_combined"] == pytest.approx(0.3)


def test_check_with_nothing_reachable_gives_one_reason_per_device(
    robot: FakeController, rig_file: Path
) -> None:
    robot.listening = False
    report = check_rig(load_rig(rig_file), **fakes(robot, ports=[]))  # type: ignore[arg-type]
    assert not report.ok
    reasons = {d.device: d.summary for d in report.failures}
    assert set(reasons) == {"arm", "dashboard", "calibration", "vacuum", "midi"}
    assert "192.0.2.10:29999" in reasons["arm"]
    assert "UR dashboard server at 192.0.2.10:29999" in reasons["dashboard"]
    assert "available: none" in reasons["midi"]


def test_check_needs_a_lab_rig() -> None:
    with pytest.raises(ValueError, match="kind: ur5"):
        check_rig(RigSpec())


def calibration_fakes(robot: FakeController) -> dict[str, object]:
    sdk = sdk_factories(robot)
    return {"receive_factory": sdk["receive"], "control_factory": sdk["control"],
            "dashboard_factory": sdk["dashboard"]}


def calibrate(robot: FakeController, rig_file: Path, answer: str = "") -> object:
    prompts: list[str] = []

    def ask(prompt: str) -> str:
        prompts.append(prompt)
        # While the operator places the finger the arm must be in freedrive.
        assert robot.calls_to("teachMode") and not robot.calls_to("endTeachMode")
        return answer

    result = calibrate_reference_pose(
        rig_file,
        ask=ask,
        interactive=lambda: True,
        now=lambda: datetime(2026, 3, 4, 5, 6, 7, tzinfo=UTC),
        **calibration_fakes(robot),
    )
    assert "B3 (MIDI 59)" in prompts[0] and "1.5 cm" in prompts[0]
    return result


def test_calibrate_writes_the_taught_pose_into_the_rig_file(
    robot: FakeController, rig_file: Path
) -> None:
    calibrate(robot, rig_file)
    assert robot.calls_to("endTeachMode")
    rig = load_rig(rig_file)
    assert rig.ur5 is not None
    assert rig.ur5.reference_pose == pytest.approx(TAUGHT_POSE)
    assert rig.ur5.calibrated_utc == "2026-03-04T05:06:07Z"
    text = rig_file.read_text()
    assert "# lab rig for tests" in text and "# written by calibrate" in text
    assert not any(name == "moveL" for _, name, _ in robot.calls)


def test_calibrate_abort_leaves_the_file_alone(robot: FakeController, rig_file: Path) -> None:
    with pytest.raises(RigError, match="aborted by the operator"):
        calibrate(robot, rig_file, answer="q")
    assert robot.calls_to("endTeachMode")
    assert rig_file.read_text() == RIG_YAML


def test_calibrate_refuses_a_stopped_arm(robot: FakeController, rig_file: Path) -> None:
    robot.protective_stopped = True
    with pytest.raises(DeviceUnavailable, match="protective stopped.*teach pendant"):
        calibrate_reference_pose(
            rig_file, ask=lambda p: "", interactive=lambda: True,
            **calibration_fakes(robot),
        )
    assert not robot.calls_to("teachMode")
    assert rig_file.read_text() == RIG_YAML


def test_calibrate_without_a_terminal_fails_before_connecting(
    robot: FakeController, rig_file: Path
) -> None:
    with pytest.raises(DeviceUnavailable, match="needs an operator at a terminal"):
        calibrate_reference_pose(
            rig_file, interactive=lambda: False,
            **calibration_fakes(robot),
        )
    assert robot.calls == []


def test_note_names() -> None:
    assert [note_name(n) for n in (59, 60, 61, 21, 108)] == ["B3", "C4", "C#4", "A0", "C8"]


class _BusyHostStream:
    """An RTDE stream at 500 Hz read by a host too busy to see two packages in a row: each
    read returns a later package, 2, 3, 2 or 4 control cycles on (the receive interface's
    `getTimestamp` only)."""

    def __init__(self) -> None:
        self.cycle = 0
        self.calls = 0

    def getTimestamp(self) -> float:  # noqa: N802
        self.cycle += (2, 3, 2, 4)[self.calls % 4]
        self.calls += 1
        return self.cycle * 0.002


def test_the_measured_stream_rate_survives_a_busy_host() -> None:
    """Timestamps step by whole control cycles, so the rate is read from their common divisor,
    not from the smallest step (which here is two cycles: 250 Hz)."""
    assert measured_rate_hz(_BusyHostStream(), window_s=0.02) == 500.0
