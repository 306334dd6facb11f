"""Physics sanity of the truth lab: moveL profiles, contact signs, energy, accuracy, resonances."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.truth import BASE_SETS, Effect
from tests.truth import kernel as K
from tests.truth.arm import ArmServo, Move, PressCommand, command, move_table
from tests.truth.catalogue import MIDI_VACUA, MOCAP_VACUA
from tests.truth.ctrl_log import simulate_stroke
from tests.truth.kernel import integrate
from tests.truth.plant import STEP_S, Plant
from tests.truth.readout import Piano

BASE = BASE_SETS["light-finger"]


def test_move_is_a_trapezoid_or_a_triangle() -> None:
    long = Move(0.0, 0.05, 0.04, 0.5)  # reaches 0.04 m/s after 0.08 s
    ramp, cruise, total, peak = long.timing
    assert (ramp, peak) == pytest.approx((0.08, 0.04))
    assert total == pytest.approx(2 * 0.08 + (0.05 - 0.04**2 / 0.5) / 0.04)
    short = Move(0.0, 0.002, 0.08, 0.5)  # d < v²/a: never reaches 0.08 m/s
    ramp, cruise, total, peak = short.timing
    assert cruise == 0.0 and peak == pytest.approx(math.sqrt(0.5 * 0.002))
    assert total == pytest.approx(2 * math.sqrt(0.002 / 0.5))
    t = np.linspace(-0.1, 1.5, 4001)
    x, v = command(t, move_table([long]))
    assert x[0] == 0.0 and x[-1] == pytest.approx(0.05)
    assert np.all(np.diff(x) >= -1e-15) and v.max() == pytest.approx(0.04)
    assert np.allclose(np.gradient(x, t), v, atol=2e-3)


def test_kernel_follows_the_same_command() -> None:
    press = PressCommand(0.1, 0.03, 0.8, 0.004, 0.0, 0.2, 0.05)
    traj = Plant(BASE, -40.0).simulate(press.moves(), press.t_end_s + 0.1, record_every=40)
    x, _ = command(traj.t_s, move_table(press.moves()))
    assert np.max(np.abs(traj["x_cmd_m"] - x)) < 1e-12
    assert np.max(np.abs(traj["x0_m"] - x)) < 1e-12  # the exact arm follows it


def test_low_acceleration_caps_the_contact_speed() -> None:
    """Braking over the last s metres caps the speed at √(2·a·s) (the study's suspect)."""
    plant = Plant(BASE, -60.0, distance_m=0.05)
    slow = simulate_stroke(plant, PressCommand(0.0, 0.08, 0.1, 0.02, 0.05, 0.0, 0.08), Piano())
    fast = simulate_stroke(plant, PressCommand(0.0, 0.08, 1.0, 0.02, 0.05, 0.0, 0.08), Piano())
    assert slow.contact_speed_mps == pytest.approx(math.sqrt(2 * 0.1 * 0.02), rel=0.03)
    assert fast.contact_speed_mps == pytest.approx(0.08, rel=0.03)


def _energy(rec: np.ndarray, p: np.ndarray) -> np.ndarray:
    s = np.maximum(rec[:, K.OUT_X1] - rec[:, K.OUT_X2] - p[K.DIST], 0.0)
    return (0.5 * p[K.M1] * rec[:, K.OUT_V1] ** 2 + 0.5 * p[K.M2] * rec[:, K.OUT_V2] ** 2
            + 0.5 * p[K.K0] * (rec[:, K.OUT_XA] - rec[:, K.OUT_X1]) ** 2
            + 0.5 * p[K.K1] * s**2 + 0.5 * p[K.K2] * rec[:, K.OUT_X2] ** 2)  # fmt: skip


def test_unforced_chain_only_loses_energy_and_contact_only_pushes() -> None:
    """Released from a squeezed state with the arm still: the finger bounces off the key."""
    p = Plant(BASE, -40.0).params()
    y0 = np.zeros(K.N_STATE)
    y0[K.X1], y0[K.X2], y0[K.V1] = 0.003, 0.001, -0.2
    empty = np.zeros((0, 8))
    rec, _, counters = integrate(y0, p, empty, np.zeros(0), 0.0, STEP_S, 48_000, 1, 1)
    energy = _energy(rec, p)
    assert energy[0] > 1e-4
    assert np.all(np.diff(energy) <= 1e-12 * energy[0])  # dissipative, to round-off
    assert energy[-1] < 0.2 * energy[0]
    assert counters[0] >= 2  # it separated and touched again
    contact = rec[:, K.OUT_FC]
    gap = rec[:, K.OUT_X1] - rec[:, K.OUT_X2]
    assert contact.min() >= 0.0  # the finger never pulls the key
    assert np.all(contact[gap < 0] == 0.0)  # and touches it only in contact


def test_adhesive_pad_pulls_at_most_its_pull_off_force() -> None:
    effect = Effect("adhesion", "pull_off", {"pull_off_n": 0.1})
    plant = Plant(BASE, -40.0, distance_m=0.003, effects=(effect,))
    press = PressCommand(0.1, 0.08, 1.0, 0.008, 0.003, 0.1, 0.08)
    traj = plant.simulate(press.moves(), press.t_end_s + 0.5, record_every=4)
    assert traj["contact_n"].min() < -0.05  # it did pull ...
    assert traj["contact_n"].min() >= -0.1 - 1e-9  # ... but never past the pull-off force
    assert traj["x2_m"].min() < -1e-4  # the key was lifted above its rest


@pytest.mark.parametrize("kind", ["hover", "lugre"])
def test_long_steps_and_halved_steps_agree(kind: str) -> None:
    if kind == "hover":
        plant = Plant(BASE, -40.0, distance_m=0.003)
    else:
        lugre = Effect("key_friction", "lugre", {
            "friction_n": 0.1, "static_friction_n": 0.15, "stribeck_velocity_mps": 0.004,
            "bristle_npm": 2e4, "bristle_damping_nspm": 15.0, "viscous_nspm": 0.05})  # fmt: skip
        plant = Plant(BASE, -40.0, effects=(lugre,), servo=ArmServo("servo", freq_hz=12, zeta=0.6))
    press = PressCommand(0.05, 0.06, 1.0, 0.01, plant.distance_m, 0.2, 0.06)
    p, table = plant.params(), move_table(press.moves())
    from tests.truth.arm import breakpoints

    breaks = breakpoints(table)
    n = int(1.2 / STEP_S) // 400 * 400
    ref, _, _ = integrate(np.zeros(8), p, table, breaks, 0.0, STEP_S / 2, 2 * n, 800, 1)
    fine, _, _ = integrate(np.zeros(8), p, table, breaks, 0.0, STEP_S, n, 400, 1)
    long, _, c = integrate(np.zeros(8), p, table, breaks, 0.0, STEP_S, n, 400, 20)
    for rec in (fine, long):
        for col in (K.OUT_X1, K.OUT_X2):
            assert np.max(np.abs(rec[:, col] - ref[:, col])) < 2e-8  # 20 nm
    assert (c[2] > 0) == (kind == "hover")  # LuGre bristles forbid long steps


@pytest.mark.parametrize("name", list(BASE_SETS))
def test_coupled_key_rings_in_band(name: str) -> None:
    """|X2/X0| peaks at 7–11 Hz at every vacuum the suite uses (the real key rings there)."""
    f = np.linspace(2.0, 30.0, 2801)
    for vacuum in sorted(set(MOCAP_VACUA) | set(MIDI_VACUA)):
        k = BASE_SETS[name].at(vacuum)
        m = np.diag([k["m1_kg"], k["m2_kg"]])
        kk = np.array([[k["k0_npm"] + k["k1_npm"], -k["k1_npm"]],
                       [-k["k1_npm"], k["k1_npm"] + k["k2_npm"]]])  # fmt: skip
        cc = np.array([[k["c0_nspm"] + k["c1_nspm"], -k["c1_nspm"]],
                       [-k["c1_nspm"], k["c1_nspm"] + k["c2_nspm"]]])  # fmt: skip
        gain = []
        for w in 2 * np.pi * f:
            b = np.array([k["k0_npm"] + 1j * w * k["c0_nspm"], 0.0])
            gain.append(abs(np.linalg.solve(-(w**2) * m + 1j * w * cc + kk, b)[1]))
        assert 7.0 <= f[int(np.argmax(gain))] <= 11.0, (name, vacuum)


def test_simulated_key_rings_at_the_linear_models_frequency() -> None:
    """A quick arm step with the finger resting: the key rings at the chain's lowest mode."""
    plant = Plant(BASE, -40.0)
    press = PressCommand(0.05, 0.2, 20.0, 0.004, 0.0, 10.0, 0.2)
    traj = plant.simulate(press.moves()[:1], 1.5, record_every=4)
    t, x2 = traj.t_s, traj["x2_m"]
    settle = (t > 0.15) & (t < 1.5)
    assert traj["contact_n"][settle].min() > 0.0  # stayed in contact (linear regime)
    xs = x2[settle] - x2[settle][-1]
    ts = t[settle]
    ups = ts[1:][(xs[:-1] < 0) & (xs[1:] >= 0)]
    f_sim = (ups.size - 1) / (ups[-1] - ups[0])
    k = BASE.at(-40.0)
    m = np.diag([k["m1_kg"], k["m2_kg"]])
    kk = np.array(
        [[k["k0_npm"] + k["k1_npm"], -k["k1_npm"]], [-k["k1_npm"], k["k1_npm"] + k["k2_npm"]]]
    )
    cc = np.array(
        [[k["c0_nspm"] + k["c1_nspm"], -k["c1_nspm"]], [-k["c1_nspm"], k["c1_nspm"] + k["c2_nspm"]]]
    )
    a = np.block(
        [[np.zeros((2, 2)), np.eye(2)], [-np.linalg.solve(m, kk), -np.linalg.solve(m, cc)]]
    )
    f_model = np.abs(np.linalg.eigvals(a).imag).min() / (2 * np.pi)
    assert 7.0 <= f_sim <= 11.0
    assert f_sim == pytest.approx(f_model, rel=0.03)


def test_mocap_clock_offset_and_rate_shift_every_frame() -> None:
    """A hidden mocap_delay: frame k shows the state at true time (k/120 − δ)/(1 + r)."""
    from tests.truth import Scenario, TakeSchedule
    from tests.truth.materialise import simulate_take

    take = TakeSchedule(speeds_mps=(0.04, 0.08), repeats=1, lead_s=1.0, tail_s=1.0)
    effect = Effect("mocap_delay", "drifting", {"delay_s": 0.02, "rate_ppm": 2000.0})
    s = Scenario("clock", "mocap", "soft-key", -40.0, 1, "strong", effect, take=take)
    presses, shifted = simulate_take(s)
    _, true = simulate_take(s.without_effect())
    for press in presses:
        half = 0.5 * (press.depth_m + press.distance_m)
        t_true = _crossing(true.t_s, true["x0_m"], press.t_start_s, half)
        t_mocap = _crossing(shifted.t_s, shifted["x0_m"], press.t_start_s, half)
        assert t_mocap == pytest.approx(t_true * (1 + 2000e-6) + 0.02, abs=2e-5)


def _crossing(t: np.ndarray, x: np.ndarray, after_s: float, level: float) -> float:
    """When x first rises through `level` after `after_s` (linear between frames)."""
    i = int(np.searchsorted(t, after_s))
    i += int(np.argmax(x[i:] >= level))
    return float(t[i - 1] + (level - x[i - 1]) / (x[i] - x[i - 1]) * (t[i] - t[i - 1]))


def test_resampling_a_fine_record_matches_recording_at_the_frames() -> None:
    from tests.truth.materialise import resample

    plant = Plant(BASE, -40.0, distance_m=0.002)
    press = PressCommand(0.2, 0.06, 1.0, 0.01, 0.002, 0.2, 0.06)
    frames = plant.simulate(press.moves(), 1.5, record_every=400)
    fine = plant.simulate(press.moves(), 1.6, record_every=40)
    again = resample(fine, frames.t_s)
    for name in ("x0_m", "x1_m", "x2_m"):
        assert np.max(np.abs(again[name] - frames[name])) < 5e-9
