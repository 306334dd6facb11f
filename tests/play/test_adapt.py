"""The online adapter on synthetic pianos: global scale and shift, local steps, bounds, forgetting."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

from pianobot.play.adapt import OnlineAdapter
from pianobot.play.corrections import RLS2, LocalCorrection

SPEEDS = np.linspace(0.01, 0.06, 201)
VACUUM = -60.0


def model_velocity(v: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """The planner's (smooth) model: 200 MIDI units per m/s."""
    return np.asarray(200.0 * np.asarray(v, dtype=np.float64), dtype=np.float64)


def model_lead(v: npt.ArrayLike) -> npt.NDArray[np.float64]:
    return np.asarray(0.02 / np.asarray(v, dtype=np.float64), dtype=np.float64)


def stepped_piano(v: float) -> int:
    """A louder piano whose map has a step the model lacks (finger and key separate above 0.04)."""
    return round(1.3 * 200.0 * v + (6.0 if v > 0.04 else 0.0))


def play(adapter: OnlineAdapter, i: int, target: float, piano: object = stepped_piano) -> tuple[float, int]:
    """Choose a stroke for `target`, play it on `piano`, let the adapter learn; (speed, played)."""
    forecast = adapter.forecast(VACUUM, SPEEDS, model_velocity(SPEEDS), model_lead(SPEEDS))
    k = adapter.choose(forecast, target)
    speed = float(SPEEDS[k])
    played = piano(speed)  # type: ignore[operator]
    adapter.observe(i, VACUUM, speed, float(model_velocity(speed)), float(model_lead(speed)), played,
                    float(model_lead(speed)) * 0.9, forecast_velocity=float(forecast.velocity[k]),
                    forecast_lead_s=float(forecast.lead_s[k]))
    return speed, played


def test_rls_learns_a_scaled_and_shifted_map_with_bounded_steps() -> None:
    rls = RLS2.prior(offset_sd=3.0, gain_sd=0.3, max_step=(2.0, 0.15), bounds=((-30, 30), (0.3, 3.0)),
                     forgetting=0.97)
    rls.update(5.0, 120.0, 1.0)  # one absurd note moves each parameter by at most its step
    assert abs(rls.theta[0]) <= 2.0 + 1e-12 and abs(rls.theta[1] - 1.0) <= 0.15 + 1e-12
    rng = np.random.default_rng(0)
    for _ in range(80):
        x = float(rng.uniform(2, 12))
        rls.update(x, round(1.6 * x + 1.0), 1.0)
    assert rls.theta[1] == pytest.approx(1.6, abs=0.1)
    assert rls.invert(17.0) == pytest.approx(10.0, abs=0.6)


def test_local_correction_reverts_to_the_prior_away_from_data_and_clips_residuals() -> None:
    local = LocalCorrection(scales=((0.001, 3.0),), noise_sd=0.5, forgetting=1.0, max_residual=10.0)
    mean, sd = local.posterior([0.03], [4.0], [0], [0.03, 0.0305, 0.04])
    assert mean[0] == pytest.approx(4.0 * 9 / (9 + 0.25))  # shrunk by the noise, like any GP
    assert 0 < mean[1] < mean[0] and mean[2] == pytest.approx(0.0, abs=1e-6)
    assert sd[0] < 0.5 and sd[2] == pytest.approx(3.0)
    clipped, _ = local.posterior([0.03], [500.0], [0], [0.03])
    assert clipped[0] <= 10.0


def test_adapter_converges_on_a_louder_piano_with_a_step_the_model_lacks() -> None:
    adapter = OnlineAdapter()
    targets = [4.0, 8.0, 18.0, 22.0, 6.0] * 8  # all reachable: 10.4 to 16.4 is the step's gap
    errors = [abs(play(adapter, i, t)[1] - t) for i, t in enumerate(targets)]
    # The first notes are off by the model's mismatch; once each loudness was met, it is kept.
    assert max(errors[:5]) >= 3.0
    assert np.mean(errors[-10:]) <= 0.5
    assert adapter.state()["velocity_gain"] != 1.0
    assert len(adapter.history) == len(targets)
    last = adapter.history[-1]
    assert {"predicted_velocity", "played_velocity", "down_velocity_mps", "velocity_offset",
            "lead_gain", "local_points"} <= set(last)
    # The lead too: the piano sounds 10 % sooner than the model says.
    forecast = adapter.forecast(VACUUM, [0.03], model_velocity([0.03]), model_lead([0.03]))
    assert forecast.lead_s[0] == pytest.approx(0.9 * float(model_lead(0.03)), rel=0.03)


def test_a_global_gain_alone_cannot_learn_the_step() -> None:
    """Without the local layer the step stays as an error: what the local layer is for."""
    targets = [4.0, 8.0, 18.0, 22.0, 6.0] * 8
    both = OnlineAdapter()
    global_only = OnlineAdapter(velocity_local=LocalCorrection(scales=((0.001, 1e-9),), noise_sd=0.5,
                                                               forgetting=0.98, max_residual=30.0))
    late = {}
    for name, adapter in (("both", both), ("global", global_only)):
        errors = [abs(play(adapter, i, t)[1] - t) for i, t in enumerate(targets)]
        late[name] = float(np.mean(errors[-20:]))
    assert late["global"] > 0.5 and late["global"] > 2 * late["both"]


def test_choose_respects_what_can_start_on_time() -> None:
    adapter = OnlineAdapter()
    forecast = adapter.forecast(VACUUM, SPEEDS, model_velocity(SPEEDS), model_lead(SPEEDS))
    allowed = SPEEDS >= 0.05
    k = adapter.choose(forecast, 4.0, allowed)  # 4 needs 0.02 m/s: too slow to start in time
    assert SPEEDS[k] == pytest.approx(0.05)
    k = adapter.choose(forecast, 4.0, np.zeros(SPEEDS.size, dtype=bool))
    assert SPEEDS[k] == SPEEDS[-1]  # nothing on time: the shortest lead


def test_forgetting_follows_a_drifting_piano_and_levels_are_kept_apart() -> None:
    adapter = OnlineAdapter()
    for i in range(30):
        play(adapter, i, 8.0, piano=lambda v: round(200 * v))
    for i in range(30, 60):
        play(adapter, i, 8.0, piano=lambda v: round(260 * v))  # the finger stiffened
    speed, played = play(adapter, 60, 8.0, piano=lambda v: round(260 * v))
    assert abs(played - 8) <= 1
    # Another vacuum level has its own local map (only the global layer is shared).
    other = adapter.forecast(-80.0, [speed], model_velocity([speed]), model_lead([speed]))
    here = adapter.forecast(VACUUM, [speed], model_velocity([speed]), model_lead([speed]))
    assert other.velocity_sd[0] > here.velocity_sd[0]
