"""The MIDI-only fit's drive starts each keystroke in flight (`physics.free_flight`): the same
MIDI outcomes as keystrokes simulated from rest."""

from __future__ import annotations

import numpy as np
import pytest

from pianobot.analysis.greybox import commanded
from pianobot.analysis.greybox.commanded import Commanded
from pianobot.analysis.greybox.keystrokes import KeystrokeBatch
from pianobot.physics.model import KeystrokeModel
from pianobot.physics.simulate import FlightStarts


def test_the_commanded_drive_started_in_flight_reads_the_same_midi(monkeypatch: pytest.MonkeyPatch) -> None:
    """The MIDI-only fit's drive starts each keystroke in flight: its outcomes are those of
    keystrokes simulated from rest (to rounding), and note-on times still count from the
    start of the motion."""
    n = 18
    rng = np.random.default_rng(5)
    batch = KeystrokeBatch(
        tuple(f"k{i}" for i in range(n)), np.full(n, -60.0), np.zeros(0), np.zeros((n, 0)), np.zeros((n, 0)),
        np.zeros((n, 0)), down_velocity_mps=rng.uniform(0.01, 0.08, n), up_velocity_mps=np.full(n, np.nan),
        acceleration_mps2=np.full(n, np.nan), depth_m=rng.uniform(0.02, 0.04, n), hold_s=np.zeros(n),
        distance_m=np.full(n, 0.05))
    model = KeystrokeModel.study().with_effect("arm_acceleration").with_effect("contact").with_effect("keybed")
    drive = {"acceleration_mps2": 0.5}
    late = Commanded(batch).predict(model, drive)
    at_rest = commanded.flight_starts

    def from_rest(*args: object, **kwargs: object) -> FlightStarts:
        s = at_rest(*args, **kwargs)  # type: ignore[arg-type]
        return FlightStarts(np.zeros_like(s.start_s), np.zeros_like(s.state), s.out_dt_s, s.step_s)

    monkeypatch.setattr(commanded, "flight_starts", from_rest)
    rest = Commanded(batch).predict(model, drive)
    assert late.sounded.sum() >= n // 2
    np.testing.assert_array_equal(late.sounded, rest.sounded)
    for got, want in ((late.on_velocity, rest.on_velocity), (late.t_on_s, rest.t_on_s),
                      (late.hold_s, rest.hold_s), (late.margin_m, rest.margin_m)):
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)
    assert np.nanmin(late.t_on_s) > 0.05 / 0.08  # counted from the start of the motion
