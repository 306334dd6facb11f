"""`pianobot rig check | calibrate`: exit codes, one line per unreachable device, JSON."""

from __future__ import annotations

import importlib.util
import json
import sys
from functools import partial
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
from cli_runner import invoke_cli as cli

from pianobot.cli import rig as rig_cli
from pianobot.rig.calibrate import calibrate_reference_pose
from pianobot.rig.check import check_rig

RIG_TESTS = Path(__file__).resolve().parents[1] / "rig"


def _load(name: str) -> ModuleType:
    """The fakes live beside the rig tests (tests/ is not a package); share one copy."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, RIG_TESTS / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


fake_rtde = _load("fake_rtde")
fake_midi = _load("fake_midi")

LAB = """\
kind: ur5
ur5:
  host: {host}
  connect_timeout_s: 1
  workspace_min_m: [-0.75, -0.35, 0.02]
  workspace_max_m: [-0.30, 0.10, 0.30]
  reference_pose: {pose}
  calibrated_utc: {when}
vacuum:
  mode: ur-analog
  regulator: {{output_channel: 0, signal: voltage, signal_span: [0, 10], kpa_span: [0, -80]}}
  monitor: {{input_channel: 0, signal: voltage, signal_span: [0, 10]}}
midi:
  api: JACK
  port: ES8
"""
POSE = [-0.5, -0.1, 0.1, 0.0, 3.14159, 0.0]




def rig_file(tmp_path: Path, host: str = "192.0.2.10", calibrated: bool = True) -> Path:
    path = tmp_path / "lab.yaml"
    path.write_text(LAB.format(
        host=host,
        pose=json.dumps(POSE) if calibrated else "null",
        when='"2026-01-01T00:00:00Z"' if calibrated else "null",
    ))
    return path


@pytest.fixture()
def robot() -> Any:
    return fake_rtde.FakeController(clock=fake_rtde.FakeClock(), pose=list(POSE))


@pytest.fixture()
def fake_devices(robot: Any, monkeypatch: pytest.MonkeyPatch) -> Any:
    midi = fake_midi.FakeMidiBackend(["Kawai ES8:Kawai ES8 MIDI 1 20:0"])
    monkeypatch.setattr(rig_cli, "check_rig", partial(
        check_rig,
        receive_factory=partial(fake_rtde.FakeReceive, robot),
        io_factory=partial(fake_rtde.FakeIO, robot),
        dashboard_factory=partial(fake_rtde.FakeDashboard, robot),
        midi_backend=lambda api: midi,
    ))
    return robot


def test_check_with_nothing_reachable_exits_2_with_one_line_per_device(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    # Nothing listens on localhost's UR ports, and no JACK server by this name exists.
    monkeypatch.setenv("JACK_DEFAULT_SERVER", "pianobot-no-such-server")
    monkeypatch.setenv("JACK_NO_START_SERVER", "1")
    code, out, err = cli(["rig", "check", str(rig_file(tmp_path, host="127.0.0.1"))],
                         capsys, monkeypatch)
    assert code == 2
    errors = [line for line in err.splitlines() if line.startswith("error:")]
    devices = [line.split(":")[1].strip() for line in errors]
    assert devices == ["arm", "dashboard", "vacuum", "midi"]
    assert "127.0.0.1:29999" in errors[0] and "127.0.0.1:29999" in errors[1]
    assert "127.0.0.1:30004" in errors[2]  # the vacuum I/O
    assert "Traceback" not in err
    assert "FAIL" in out


def test_check_json_on_a_healthy_rig_exits_0(
    tmp_path: Path, fake_devices: Any, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    code, out, err = cli(["rig", "check", str(rig_file(tmp_path)), "--json"], capsys, monkeypatch)
    assert code == 0, err
    report = json.loads(out)
    assert report["ok"] is True and report["host"] == "192.0.2.10"
    assert [d["device"] for d in report["devices"]] == [
        "arm", "dashboard", "calibration", "vacuum", "midi"
    ]
    assert report["devices"][0]["speed_scaling"] == 1.0
    assert report["devices"][3]["monitor_kpa"] == pytest.approx(0.0)
    assert report["devices"][3]["kpa_span"] == [0.0, -80.0]


def test_check_json_still_exits_2_when_a_device_fails(
    tmp_path: Path, fake_devices: Any, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    fake_devices.emergency_stopped = True
    code, out, err = cli(["rig", "check", str(rig_file(tmp_path)), "--json"], capsys, monkeypatch)
    assert code == 2
    assert json.loads(out)["devices"][0]["ok"] is False
    assert err.strip().splitlines() == [
        line for line in err.strip().splitlines() if line.startswith("error: arm:")
    ]


@pytest.mark.parametrize(("target", "message"), [
    ("sim", "needs a lab rig file (kind: ur5)"),
    ("missing.yaml", "missing.yaml"),
])
def test_check_bad_rig_argument_exits_2_on_one_line(
    target: str, message: str, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    code, out, err = cli(["rig", "check", target], capsys, monkeypatch)
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and message in err


def test_calibrate_without_a_terminal_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(sys.stdin, "isatty", lambda: False, raising=False)
    path = rig_file(tmp_path, calibrated=False)
    before = path.read_text()
    code, out, err = cli(["rig", "calibrate", str(path)], capsys, monkeypatch)
    assert code == 2
    assert err.strip().splitlines() == [
        f"error: {path}: calibration needs an operator at a terminal to place the finger "
        "(stdin is not a TTY)"
    ]
    assert path.read_text() == before


def test_calibrate_writes_the_pose_and_reports_it(
    tmp_path: Path, robot: Any, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(rig_cli, "calibrate_reference_pose", partial(
        calibrate_reference_pose,
        ask=lambda prompt: "",
        interactive=lambda: True,
        receive_factory=partial(fake_rtde.FakeReceive, robot),
        control_factory=partial(fake_rtde.FakeControl, robot),
        dashboard_factory=partial(fake_rtde.FakeDashboard, robot),
    ))
    path = rig_file(tmp_path, calibrated=False)
    code, out, err = cli(["rig", "calibrate", str(path), "--json"], capsys, monkeypatch)
    assert code == 0, err
    result = json.loads(out)
    assert result["reference_pose"] == pytest.approx(POSE)
    assert result["reference_note"] == 59 and result["calibrated_utc"].endswith("Z")
    assert "reference_pose: [-0.5, -0.1, 0.1" in path.read_text()
