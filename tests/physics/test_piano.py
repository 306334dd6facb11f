"""Digital piano readout: sensor timing → velocity, note-off, silent keys, MIDI clock."""

from __future__ import annotations

import numpy as np
import pytest

from pianobot.physics.piano import PianoParams, on_velocity_from_speed, piano_events


def _tri(t: np.ndarray, peak_m: float, speed_mps: float, t_top_s: float = 0.5) -> np.ndarray:
    """Key goes down at `speed_mps` until `peak_m`, holds, comes back at the same speed."""
    down = np.minimum(speed_mps * t, peak_m)
    top = min(speed_mps * t_top_s, peak_m)
    up = np.clip(top - speed_mps * (t - t_top_s), 0.0, peak_m)
    return np.where(t < t_top_s, down, up)


def test_velocity_curve_is_monotone_bounded_and_saturates() -> None:
    p = PianoParams(curve_exponent=2.0, curve_saturation=1.5)
    s = np.linspace(0.0, 1.0, 400)
    v = on_velocity_from_speed(s, p)
    assert v.min() >= 1 and v.max() == 127
    assert np.all(np.diff(v) >= 0)
    assert on_velocity_from_speed(0.0, p) == 1
    linear = PianoParams()
    assert on_velocity_from_speed(linear.full_scale_speed_mps / 2, linear) in (63, 64)


def test_note_on_velocity_from_transit_time_and_note_off() -> None:
    p = PianoParams(jitter_s=0.0)
    t = np.arange(0.0, 2.0, 1e-3)
    slow, fast = _tri(t, 0.008, 0.01), _tri(t, 0.008, 0.05)
    ev = piano_events(t, np.vstack([slow, fast]), p, note=60)
    for events in ev:
        assert [e.type for e in events] == ["note_on", "note_off"]
        assert all(e.note == 60 for e in events)
    assert ev[0][0].velocity < ev[1][0].velocity
    assert ev[1][0].velocity == on_velocity_from_speed(0.05, p)
    # note-on when the key passes the lower sensor: 3.8 mm at 10 mm/s = 0.38 s
    assert abs(ev[0][0].t_s - p.lower_sensor_m / 0.01) <= 1e-3
    # timestamps on the 1 ms MIDI clock
    for e in ev[0] + ev[1]:
        assert abs(e.t_s * 1000 - round(e.t_s * 1000)) < 1e-6


def test_silent_when_the_key_never_reaches_the_lower_sensor() -> None:
    p = PianoParams()
    t = np.arange(0.0, 1.0, 1e-3)
    assert piano_events(t, _tri(t, 0.9 * p.lower_sensor_m, 0.02), p) == [[]]


def test_jitter_only_with_an_rng_and_never_early() -> None:
    p = PianoParams(jitter_s=5e-4)
    t = np.arange(0.0, 1.0, 1e-3)
    x = _tri(t, 0.008, 0.02)
    exact = piano_events(t, x, p)[0]
    jittered = piano_events(t, x, p, rng=np.random.default_rng(1))[0]
    assert len(exact) == len(jittered) == 2
    for a, b in zip(exact, jittered, strict=True):
        assert 0.0 <= b.t_s - a.t_s <= 1e-3 + 1e-9


def test_one_velocity_curve_rounded_or_continuous() -> None:
    """The curve before rounding is smooth, hits the curve's fixed points, and rounds to the MIDI value."""
    for p in (PianoParams(), PianoParams(curve_exponent=2.0, curve_saturation=1.0),
              PianoParams(full_scale_speed_mps=0.2, curve_exponent=0.7, curve_saturation=3.0)):
        fs = p.full_scale_speed_mps
        s = np.linspace(0.0, 2.0 * fs, 1001)
        smooth = on_velocity_from_speed(s, p, rounded=False)
        raw = on_velocity_from_speed(s, p, rounded=False, clipped=False)
        midi = on_velocity_from_speed(s, p)
        assert smooth.dtype == np.float64 and midi.dtype == np.int64
        assert np.array_equal(midi, np.clip(np.rint(raw), 1, 127).astype(np.int64))
        assert np.array_equal(smooth, np.clip(raw, 1.0, 127.0))
        assert np.all(np.diff(raw) > 0.0)  # strictly increasing: invertible
        assert np.any((smooth != np.rint(smooth)) & (smooth > 1.0) & (smooth < 127.0))
        # Full-scale speed is velocity 127 for every exponent and saturation.
        assert abs(on_velocity_from_speed(fs, p, rounded=False) - 127.0) < 1e-9
        # Scalars give scalars of the same value.
        assert on_velocity_from_speed(float(s[300]), p, rounded=False) == smooth[300]
        assert on_velocity_from_speed(float(s[300]), p) == midi[300]
    linear = PianoParams()
    assert on_velocity_from_speed(linear.full_scale_speed_mps / 2, linear, rounded=False) == 63.5
    # Beyond full scale the unclipped linear curve goes on (a fit's slope), the clipped one stops.
    assert on_velocity_from_speed(0.09, linear, rounded=False, clipped=False) > 190.0
    assert on_velocity_from_speed(0.09, linear, rounded=False) == 127.0


def test_a_rounded_velocity_is_always_clipped() -> None:
    with pytest.raises(ValueError, match="rounded"):
        on_velocity_from_speed(0.05, PianoParams(), clipped=False)
