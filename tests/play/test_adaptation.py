"""`play --adapt` on a world that differs from the planner's model by about 30 % (issue 7).

The planner's model is the GP fitted on the default world (conftest); the changed world's piano
is 30 % more sensitive and its finger 30 % stiffer. The song is the 60-note etude at 90 bpm, in
robot notation (whole notes: every loudness the finger has is reachable in time) and in half
notes (where one soft finger cannot play a quiet note after another in time on this world).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pianobot.analysis.learn.training import LearnedPredictor
from pianobot.io.midifile import write_song
from pianobot.physics.msd import MSDParams
from pianobot.physics.trajectory import Press, press_duration_s
from pianobot.physics.world import World, WorldConfig
from pianobot.plan import key_change_s
from pianobot.play import PlayResult, PlaySettings, play_rig, play_song
from pianobot.play.library import ROBOT_BEAT, etude

PLAY_RIG = Path(__file__).resolve().parents[2] / "experiments" / "rigs" / "sim-play.yaml"
THIRDS = ((0, 20), (20, 40), (40, 60))


def changed_world(seed: int = 0) -> World:
    """The default world with a 30 % more sensitive velocity curve and a 30 % stiffer finger."""
    base = World.default(seed).model
    msd = MSDParams()
    config = WorldConfig(
        piano={"full_scale_speed_mps": base.piano.full_scale_speed_mps / 1.3},
        msd={"k1_a_npm": 1.3 * msd.k1_a_npm, "k1_b_npm_per_kpa": 1.3 * msd.k1_b_npm_per_kpa},
    )
    return World(config, seed)


@pytest.fixture(scope="module")
def etudes(fitted_model: LearnedPredictor, tmp_path_factory: pytest.TempPathFactory) -> dict[str, PlayResult]:
    """The etude in whole and half notes on the changed world, without and with adaptation."""
    data = tmp_path_factory.mktemp("etudes")
    out = {}
    for notation, beat in (("whole", ROBOT_BEAT), ("half", 2.0)):
        spec = etude(60, beat=beat)
        song = write_song(data / f"etude-{notation}.mid", spec.to_notes(), tempo_bpm=spec.tempo_bpm)
        for adapt in (False, True):
            # No warm-up: this is about --adapt correcting a model that is wrong for this piano
            # (a warm-up would have learned it first); the written tempo, to see what it allows.
            result = play_song(song, data_dir=data, model=fitted_model, world=changed_world(), rig=PLAY_RIG,
                               seed=0, adapt=adapt, warmup=0, tempo="written")
            out[f"{notation}-{'adapted' if adapt else 'fixed'}"] = result
            score = result.score
            assert score is not None
            print(f"etude60 {notation} notes, {'adapted' if adapt else 'fixed'}: velocity MAE by third "
                  f"{[round(mae_of(result, a, b), 2) for a, b in THIRDS]}, F1 {score.f1:.3f}, "
                  f"onset RMS {score.onset_rms_ms:.1f} ms")
    return out


def mae_of(result: PlayResult, start: int, stop: int) -> float:
    assert result.score is not None
    return result.score.velocity_mae_between(start, stop)


def thirds(result: PlayResult) -> list[float]:
    return [mae_of(result, a, b) for a, b in THIRDS]


def test_the_planner_model_and_the_changed_world_differ(fitted_model: LearnedPredictor) -> None:
    """The planner never sees the world: at a loud stroke its prediction is far off."""
    speed = 0.06
    predicted = float(fitted_model.predict(pd.DataFrame({
        "down_velocity_mps": [speed], "vacuum_kpa": [-60.0], "hold_s": [0.0], "distance_m": [0.002],
        "acceleration_mps2": [2.0]}))["on_velocity"].iloc[0])
    actual = changed_world().keystroke(Press(0.002, 0.025, speed, 0.7, 2.0), -60.0, note=60, key="probe").on_velocity
    assert actual is not None and abs(actual - predicted) > 0.3 * predicted


def test_adaptation_meets_the_issue_criterion(etudes: dict[str, PlayResult]) -> None:
    """Last third at most half the first, and below the non-adaptive run's last third."""
    fixed, adapted = thirds(etudes["whole-fixed"]), thirds(etudes["whole-adapted"])
    assert adapted[2] <= 0.5 * adapted[0]
    assert adapted[2] < fixed[2]
    assert all(a < 0.3 * f for a, f in zip(adapted, fixed, strict=True))
    # Timing: the stiffer finger sounds sooner; the corrected lead brings the notes back on time.
    fixed_score, adapted_score = etudes["whole-fixed"].score, etudes["whole-adapted"].score
    assert fixed_score is not None and adapted_score is not None
    assert fixed_score.f1 < 0.5 and adapted_score.f1 >= 0.95


def test_the_adaptation_is_recorded_in_the_run(etudes: dict[str, PlayResult]) -> None:
    performance = etudes["whole-adapted"].performance
    assert performance is not None
    history = pd.DataFrame(performance.adaptation)
    assert len(history) == 60 and list(history["note_index"]) == list(range(60))
    assert history["velocity_gain"].iloc[-1] != 1.0 and history["local_points"].iloc[-1] == 60
    stored = pd.read_parquet(performance.run_path / "adaptation.parquet")
    assert len(stored) == 60 and {"predicted_velocity", "played_velocity", "down_velocity_mps"} <= set(stored)
    # What the adapter expected got close to what the piano played.
    late = stored.iloc[40:]
    assert float((late["predicted_velocity"] - late["played_velocity"]).abs().mean()) < 1.0


def test_in_half_notes_adaptation_gets_what_the_tempo_allows(etudes: dict[str, PlayResult]) -> None:
    """Half notes at 90 bpm: quiet notes one after another cannot be played in time here.

    The slowest stroke that still fits one half note after the other (the press, the arm's
    recovery and the move to the next key within the beat) already sounds louder on the
    changed world than more than half of the song's targets, so those notes keep an error no model can
    remove; the adapted run is still far better than the fixed one in every third.
    """
    adapted_result = etudes["half-adapted"]
    plan = adapted_result.plan
    assert plan.geometry is not None
    settings, rig = PlaySettings(), play_rig(PLAY_RIG)
    beat_s = float(np.diff(plan.notes["onset_s"].to_numpy(float)).min())
    slack = beat_s + settings.max_late_s - key_change_s(60, 62, rig) - settings.recovery_s
    speeds = np.linspace(0.01, 0.06, 101)
    fits = np.array([press_duration_s(plan.geometry.press(float(v), 0.0)) <= slack for v in speeds])
    slowest = float(speeds[np.argmax(fits)])
    vacuum = float(plan.notes["vacuum_kpa"].iloc[0])
    world = changed_world()
    reachable = [world.keystroke(plan.geometry.press(float(v), 0.0), vacuum, note=60, key=f"floor{i}").on_velocity
                 for i, v in enumerate(np.linspace(slowest, 0.06, 12))]
    quietest = min(v for v in reachable if v is not None)
    targets = plan.notes["target_velocity"].to_numpy(float)
    assert np.mean(targets < quietest - 1.0) >= 0.5
    fixed, adapted = thirds(etudes["half-fixed"]), thirds(adapted_result)
    # The fixed run's scheduler takes strokes up to a velocity step louder where time is short,
    # which trims its error in the tight middle third; the adapted run still halves it overall.
    assert sum(adapted) < 0.5 * sum(fixed)
    assert all(a < 0.55 * f for a, f in zip(adapted, fixed, strict=True))
    assert adapted[2] < 0.3 * fixed[2]
    assert adapted_result.score is not None and adapted_result.score.f1 >= 0.95
