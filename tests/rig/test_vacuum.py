"""Vacuum regulators: analog over a fake RTDE I/O, manual with a scripted operator.

The regulator's behaviour on a real UR (domains, spans, settling) is tested against the
emulated controller in test_ur5_emulated_vacuum.py; here the bookkeeping.
"""

from __future__ import annotations

import pytest
from fake_rtde import FakeClock, FakeController, FakeIO, FakeReceive

from pianobot.rig.errors import DeviceUnavailable, RigError, SafetyViolation
from pianobot.rig.protocols import Vacuum
from pianobot.rig.vacuum import AnalogVacuum, CommandedVacuum, ManualVacuum, SignalSpan

HOST = "192.0.2.10"
VOLTS_100 = SignalSpan("voltage", (0.0, 10.0), (0.0, -100.0))
SMC_ITV2090 = SignalSpan("voltage", (0.0, 10.0), (-1.3, -80.0))
MILLIAMPS_80 = SignalSpan("current", (4.0, 20.0), (0.0, -80.0))


@pytest.fixture()
def robot() -> FakeController:
    return FakeController(clock=FakeClock())


def analog(robot: FakeController, command: SignalSpan = VOLTS_100, *, read_back: bool = True,
           **options: float) -> AnalogVacuum:
    # The fake regulator's monitor repeats its command signal: same span as the command.
    return AnalogVacuum(
        command,
        io=FakeIO(robot, HOST),
        receive=FakeReceive(robot, HOST) if read_back else None,
        clock=robot.clock,
        output_channel=1,
        monitor=command if read_back else None,
        input_channel=0 if read_back else None,
        **options,  # type: ignore[arg-type]
    )


def test_signal_span_round_trips_and_refuses_out_of_range() -> None:
    assert VOLTS_100.value_for(-40.0) == pytest.approx(4.0)
    assert VOLTS_100.kpa_for(4.0) == pytest.approx(-40.0)
    assert MILLIAMPS_80.value_for(-40.0) == pytest.approx(12.0)
    assert MILLIAMPS_80.ur_ratio(12.0) == pytest.approx(0.5)  # the UR drives 4-20 mA over 0..1
    with pytest.raises(SafetyViolation, match=r"-120 kPa is outside the regulator range \[-100, 0\]"):
        VOLTS_100.value_for(-120.0)
    with pytest.raises(SafetyViolation):
        VOLTS_100.value_for(10.0)
    # Between atmospheric and the span's near end the regulator does its closest: the end.
    assert SMC_ITV2090.value_for(0.0) == pytest.approx(0.0)
    assert SMC_ITV2090.value_for(-1.0) == pytest.approx(0.0)
    assert SMC_ITV2090.value_for(-80.0) == pytest.approx(10.0)


def test_analog_sets_the_output_ratio_and_waits_for_the_read_back(robot: FakeController) -> None:
    vacuum = analog(robot, settle_timeout_s=10.0, tolerance_kpa=1.0)
    assert isinstance(vacuum, Vacuum)
    measured = vacuum.set_kpa(-60.0)
    assert robot.calls_to("setAnalogOutputVoltage") == [(1, pytest.approx(0.6))]
    assert measured == pytest.approx(-60.0, abs=1.0)
    # A first-order regulator (tau 0.5 s) is within 1 kPa of a 60 kPa step after ~2.1 s.
    assert 2.0 < robot.clock.now() < 3.0


def test_a_current_regulator_is_driven_in_the_current_domain(robot: FakeController) -> None:
    vacuum = analog(robot, MILLIAMPS_80, read_back=False)
    vacuum.set_kpa(-20.0)
    assert robot.calls_to("setAnalogOutputCurrent") == [(1, pytest.approx(0.25))]  # 8 mA
    assert robot.calls_to("setAnalogOutputVoltage") == []
    assert robot.analog_out_value(1) == pytest.approx(8.0)
    assert vacuum.describe()["signal"] == "current"


def test_analog_settle_timeout_reports_the_last_reading(robot: FakeController) -> None:
    robot.regulator_gain = 0.8  # the regulator only reaches 80 % of the setpoint
    vacuum = analog(robot, settle_timeout_s=5.0, tolerance_kpa=2.0)
    with pytest.raises(RigError, match=r"did not settle at -50 ± 2 kPa within 5 s \(last reading -40\.0"):
        vacuum.set_kpa(-50.0)


def test_analog_without_read_back_returns_the_commanded_level(robot: FakeController) -> None:
    vacuum = analog(robot, read_back=False, settle_timeout_s=3.0)
    assert vacuum.set_kpa(-20.0) == -20.0
    assert robot.analog_out[1] == pytest.approx(0.2)
    assert robot.clock.now() == 0.0  # the station's settle pause does the waiting
    assert vacuum.read_kpa() is None


def test_analog_refused_output_is_an_error_and_vent_never_raises(robot: FakeController) -> None:
    vacuum = analog(robot)
    robot.connected = False
    with pytest.raises(RigError, match="refused analog output 1"):
        vacuum.set_kpa(-10.0)
    vacuum.vent()  # must not raise
    robot.connected = True
    vacuum.vent()
    assert robot.analog_out[1] == 0.0


def test_read_back_needs_a_receive_interface_and_both_halves(robot: FakeController) -> None:
    with pytest.raises(DeviceUnavailable, match="read-back needs"):
        AnalogVacuum(VOLTS_100, io=FakeIO(robot, HOST), clock=robot.clock, monitor=VOLTS_100,
                     input_channel=0)
    with pytest.raises(DeviceUnavailable, match="needs both its span and its input channel"):
        AnalogVacuum(VOLTS_100, io=FakeIO(robot, HOST), clock=robot.clock, input_channel=0)


def test_manual_asks_the_operator_and_takes_their_reading() -> None:
    answers = iter(["", "abc", "-38.5"])
    prompts: list[str] = []

    def ask(prompt: str) -> str:
        prompts.append(prompt)
        return next(answers)

    notices: list[str] = []
    vacuum = ManualVacuum(ask=ask, interactive=lambda: True, notify=notices.append)
    assert vacuum.set_kpa(-20.0) == -20.0
    assert "Set the vacuum regulator to -20 kPa" in prompts[0]
    assert vacuum.set_kpa(-20.0) == -20.0  # unchanged: not asked again
    assert len(prompts) == 1
    assert vacuum.set_kpa(-40.0) == -38.5
    assert "Not a number: 'abc'" in prompts[2]
    vacuum.vent()
    assert notices == ["Vent the finger: set the vacuum regulator to 0 kPa."]


def test_manual_without_a_terminal_fails_clearly() -> None:
    vacuum = ManualVacuum(ask=lambda prompt: "", interactive=lambda: False)
    with pytest.raises(DeviceUnavailable, match="needs an operator at a terminal"):
        vacuum.set_kpa(-20.0)


def test_manual_end_of_input_is_unavailable() -> None:
    def closed(prompt: str) -> str:
        raise EOFError

    vacuum = ManualVacuum(ask=closed, interactive=lambda: True)
    with pytest.raises(DeviceUnavailable, match="end of input"):
        vacuum.set_kpa(-20.0)


def test_commanded_vacuum_only_records() -> None:
    vacuum = CommandedVacuum()
    assert vacuum.set_kpa(-30.0) == -30.0
    vacuum.vent()
    assert vacuum.level_kpa == 0.0
