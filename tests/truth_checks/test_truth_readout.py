"""The truth lab's digital piano: contacts, velocity curves, note-off, re-arming."""

from __future__ import annotations

import numpy as np
import pytest

from tests.truth.readout import Piano, VelocityCurve, read_key

PIANO = Piano()


def _stroke(
    speed_mps: float, bottom_m: float = 0.008, hold_s: float = 0.2
) -> tuple[np.ndarray, np.ndarray]:
    """A key pushed down at a constant speed, held, and released at the same speed."""
    t_down = bottom_m / speed_mps
    t = np.linspace(0.0, 2 * t_down + hold_s + 0.1, 40_001)
    x = np.minimum(speed_mps * t, bottom_m)
    x = np.minimum(x, np.maximum(bottom_m - speed_mps * (t - t_down - hold_s), 0.0))
    return t, x


@pytest.mark.parametrize("curve", [
    VelocityCurve(),
    VelocityCurve("tanh", exponent=1.8, saturation=1.0),
    VelocityCurve("rational", knee=0.08),
])  # fmt: skip
def test_velocity_grows_with_key_speed(curve: VelocityCurve) -> None:
    piano = Piano(curve=curve)
    speeds = np.geomspace(0.002, 0.3, 40)
    velocities = []
    for s in speeds:
        events = read_key(piano, *_stroke(float(s)))
        on = [e for e in events if e.kind == "note_on"]
        assert len(on) == 1
        assert on[0].speed_mps == pytest.approx(s, rel=1e-3)  # the transit speed is measured
        velocities.append(on[0].velocity)
    assert np.all(np.diff(velocities) >= 0) and 1 <= min(velocities) and max(velocities) <= 127
    assert velocities[-1] > velocities[0]


def test_note_on_at_the_lower_contact_and_off_at_the_release_depth() -> None:
    t, x = _stroke(0.02)
    on, off = read_key(PIANO, t, x)
    assert on.kind == "note_on" and off.kind == "note_off"
    assert on.t_s == pytest.approx(PIANO.lower_m / 0.02 + PIANO.latency_s, abs=1e-5)
    t_up = 0.008 / 0.02 + 0.2 + (0.008 - PIANO.release_m) / 0.02
    assert off.t_s == pytest.approx(t_up + PIANO.latency_s, abs=1e-5)
    assert on.velocity == round(127 * 0.02 / PIANO.full_scale_mps)


def test_a_key_that_misses_the_lower_contact_is_silent() -> None:
    assert read_key(PIANO, *_stroke(0.05, bottom_m=0.9 * PIANO.lower_m)) == []


def test_bounce_below_the_upper_contact_does_not_strike_twice_but_a_new_press_does() -> None:
    t = np.linspace(0.0, 1.0, 20_001)
    lo, hi = PIANO.lower_m, PIANO.upper_m
    between = 0.5 * (PIANO.upper_m + PIANO.release_m)  # above the release depth, below the upper
    bounce = np.interp(
        t, [0, 0.2, 0.3, 0.4, 0.5, 0.9], [0, 1.2 * lo, between, 1.2 * lo, 1.2 * lo, 0]
    )
    events = read_key(PIANO, t, bounce)
    assert [e.kind for e in events] == ["note_on", "note_off"]  # the note stopped, no re-strike
    again = np.interp(
        t, [0, 0.2, 0.3, 0.4, 0.5, 0.9], [0, 1.2 * lo, 0.5 * hi, 1.2 * lo, 1.2 * lo, 0]
    )
    events = read_key(PIANO, t, again)
    assert [e.kind for e in events] == ["note_on", "note_off", "note_on", "note_off"]
