"""The emulated controller, driven by the real ur_rtde client (no pianobot code under test).

These pin down what the emulator does, so that the pianobot tests against it test pianobot:
the protocol handshake at each controller generation's rate, UR's moveL profile (checked
against pianobot's own trapezoid, written independently), the slider and pauses scaling time,
stops, the input-register ownership, the analog domains, and that an instance ends on its own.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import pytest

from hardware_emulator import CB3, ESERIES, EmulatedUR
from hardware_emulator.fixtures import EmulatorFactory
from pianobot.physics.trajectory import move_profile


@contextmanager
def clients(host: str, *, control: bool = True) -> Iterator[tuple[Any, Any]]:
    import rtde_control
    import rtde_receive

    receive = rtde_receive.RTDEReceiveInterface(host)
    ctrl = rtde_control.RTDEControlInterface(host) if control else None
    try:
        yield receive, ctrl
    finally:
        if ctrl is not None:
            ctrl.stopScript()
            ctrl.disconnect()
        receive.disconnect()


def wait_for(condition: Any, timeout_s: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.005)
    return False


@pytest.mark.parametrize(("generation", "rate_hz", "version"), [
    (CB3, 125.0, "3.15.7.106331"), (ESERIES, 500.0, "5.11.1.108318"),
])
def test_real_clients_connect_at_the_controllers_rate(
    ur_emulator: EmulatorFactory, generation: str, rate_hz: float, version: str,
) -> None:
    import dashboard_client

    ur = ur_emulator(generation=generation)
    with clients(ur.host) as (receive, control):
        assert control.isConnected() and control.isProgramRunning()
        assert ur.output_frequencies() == [rate_hz, rate_hz]  # ur_rtde's -1: auto
        stamps = [receive.getTimestamp()]
        while len(stamps) < 30:
            if (ts := receive.getTimestamp()) != stamps[-1]:
                stamps.append(ts)
            time.sleep(0.0002)
        cycles = np.diff(stamps) * rate_hz  # a busy host may miss one: whole cycles apart
        assert np.allclose(cycles, np.round(cycles), atol=1e-6) and min(cycles) == pytest.approx(1)
        dashboard = dashboard_client.DashboardClient(ur.host)
        dashboard.connect()
        assert dashboard.polyscopeVersion() == version
        assert dashboard.programState().startswith("PLAYING")
        dashboard.disconnect()
    assert ur.counts()["programs"] == 1


def test_movel_follows_urs_trapezoid(ur_emulator: EmulatorFactory) -> None:
    ur = ur_emulator()
    with clients(ur.host) as (receive, control):
        start = receive.getActualTCPPose()
        target = [*start[:2], start[2] - 0.03, *start[3:]]
        t0 = receive.getTimestamp()
        assert control.moveL(target, 0.05, 0.4)  # synchronous: returns on arrival
        # The receive stream may deliver the arrival cycle a little after moveL returns.
        deadline = time.monotonic() + 2.0
        while abs(receive.getActualTCPPose()[2] - target[2]) > 1e-9 and time.monotonic() < deadline:
            time.sleep(0.002)
        assert receive.getActualTCPPose()[2] == pytest.approx(target[2], abs=1e-9)
        truth = ur.truth_between(t0, receive.getTimestamp())
    t = np.array([ts for ts, _ in truth])
    z = np.array([pose[2] for _, pose in truth])
    moving = np.flatnonzero(np.abs(np.diff(z)) > 0)
    t_start = t[moving[0]]  # the last cycle at rest before the first step
    profile = move_profile(0.03, 0.05, 0.4)
    expected, _ = profile.sample(t - t_start)
    assert np.max(np.abs((start[2] - z) - expected)) < 1e-9
    assert t[moving[-1] + 1] - t_start == pytest.approx(profile.duration_s, abs=0.002)


def test_slider_limiter_and_pause_scale_time(ur_emulator: EmulatorFactory) -> None:
    ur = ur_emulator(speed_slider=0.5)
    with clients(ur.host) as (receive, control):
        assert receive.getTargetSpeedFraction() == 0.5
        assert receive.getSpeedScaling() == 1.0 and receive.getSpeedScalingCombined() == 0.5
        start = receive.getActualTCPPose()
        target = [*start[:2], start[2] - 0.02, *start[3:]]
        t0 = receive.getTimestamp()
        assert control.moveL(target, 0.1, 1.0)
        nominal = move_profile(0.02, 0.1, 1.0).duration_s
        assert receive.getTimestamp() - t0 == pytest.approx(nominal / 0.5, abs=0.02)
        # A pause ramps the trajectory to a halt; ur_rtde's combined scaling reads 0.
        assert control.moveL(start, 0.01, 1.0, True)
        time.sleep(0.1)
        ur.pause()
        assert wait_for(lambda: receive.getRuntimeState() == 4)  # PAUSED
        held = receive.getActualTCPPose()[2]
        time.sleep(0.1)
        assert receive.getActualTCPPose()[2] == held
        assert receive.getSpeedScalingCombined() == 0.0 and not control.isProgramRunning()
        assert control.moveL(start, 0.1, 1.0) is False  # ur_rtde: "script is not running"
        ur.resume()
        assert wait_for(lambda: not control.getAsyncOperationProgressEx().isAsyncOperationRunning())
        # The receive stream may still be one cycle behind the controller's "done" on a busy host.
        assert wait_for(lambda: receive.getActualTCPPose()[2] == pytest.approx(start[2], abs=1e-9), timeout_s=1.0)


def test_a_protective_stop_refuses_motion_until_unlocked(ur_emulator: EmulatorFactory) -> None:
    import dashboard_client

    ur = ur_emulator()
    with clients(ur.host) as (receive, control):
        start = receive.getActualTCPPose()
        ur.fail_on_move(1, "protective_stop", fraction=0.3)
        assert control.moveL([*start[:2], start[2] - 0.02, *start[3:]], 0.05, 0.5) is False
        # The receive stream may show the stop a cycle after the control stream did.
        assert wait_for(lambda: receive.isProtectiveStopped() and receive.getSafetyMode() == 3)
        stopped_at = receive.getActualTCPPose()[2]
        assert start[2] - 0.02 < stopped_at < start[2] - 0.005
        dashboard = dashboard_client.DashboardClient(ur.host)
        dashboard.connect()
        assert dashboard.safetystatus() == "Safetystatus: PROTECTIVE_STOP"
        dashboard.unlockProtectiveStop()
        dashboard.play()
        dashboard.disconnect()
        assert wait_for(lambda: control.isProgramRunning())
        assert wait_for(lambda: not control.getAsyncOperationProgressEx().isAsyncOperationRunning()
                        and abs(receive.getActualTCPPose()[2] - (start[2] - 0.02)) < 1e-9)
        # The script answers the resumed move a cycle after the arm arrives. The clean-up's
        # stopScript waits for that: sent earlier, it was ignored 1 run in 4 (a 300 s hang).
        assert wait_for(ur.script_waiting)


def test_input_registers_have_one_writer(ur_emulator: EmulatorFactory) -> None:
    import rtde_io

    ur = ur_emulator()
    first = rtde_io.RTDEIOInterface(ur.host)
    with pytest.raises(RuntimeError, match="already in use"):
        rtde_io.RTDEIOInterface(ur.host)
    first.disconnect()
    assert wait_for(lambda: ur.counts()["connections"]["rtde"] == 2)
    time.sleep(0.05)  # the emulator sees the first client go
    second = rtde_io.RTDEIOInterface(ur.host)
    assert second.setAnalogOutputVoltage(0, 0.5)
    second.disconnect()


def test_analog_outputs_follow_their_domain_and_drive_the_regulator(
    ur_emulator: EmulatorFactory,
) -> None:
    import rtde_io

    ur = ur_emulator()  # an SMC ITV2090 on output 0: 0-10 V = 0 to -80 kPa, monitor 1-5 V
    io = rtde_io.RTDEIOInterface(ur.host)
    with clients(ur.host, control=False) as (receive, _):
        io.setAnalogOutputVoltage(0, 0.5)
        io.setAnalogOutputCurrent(1, 0.25)
        assert wait_for(lambda: receive.getStandardAnalogOutput0() == pytest.approx(5.0))
        assert wait_for(lambda: receive.getStandardAnalogOutput1() == pytest.approx(8.0))  # mA
        assert ur.get("analog_domain") == ["voltage", "current"]
        assert wait_for(lambda: abs(ur.regulator_kpa() + 40.0) < 0.5)
        assert receive.getStandardAnalogInput0() == pytest.approx(3.0, abs=0.05)  # 1-5 V monitor
        io.setAnalogOutputCurrent(0, 0.5)  # the wrong domain for this regulator: no vacuum
        assert wait_for(lambda: abs(ur.regulator_kpa() or 0.0) < 0.5)
    io.disconnect()


def test_dropped_links_are_refused_for_the_outage_then_accepted(
    ur_emulator: EmulatorFactory,
) -> None:
    ur = ur_emulator()
    with clients(ur.host) as (receive, control):
        ur.drop_links(0.5)
        assert wait_for(lambda: not receive.isConnected())
        with pytest.raises(RuntimeError):
            receive.reconnect()
        time.sleep(0.6)
        assert receive.reconnect() and receive.isConnected()
        if not control.isConnected():
            assert control.reconnect()
        assert wait_for(lambda: control.isProgramRunning())


def test_instances_get_their_own_address_and_end_by_themselves() -> None:
    pytest.importorskip("rtde_receive")
    first = EmulatedUR(lifetime_s=0.5).start()
    second = EmulatedUR(lifetime_s=30.0).start()
    try:
        assert first.host != second.host and first.host.startswith("127.")
        assert wait_for(lambda: not first.alive, timeout_s=10.0)
        assert second.alive
    finally:
        first.stop()
        second.stop()
    assert not second.alive
    second.stop()  # stopping twice is harmless
    assert math.isfinite(first.lifetime_s)
