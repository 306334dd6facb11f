"""`play` end to end on the sim rig: model planner vs the naive baseline, adaptation, reports."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pianobot.analysis.learn import LearnedPredictor
from pianobot.errors import InputError
from pianobot.io.midifile import Note, read_song, write_song
from pianobot.physics.msd import MSDParams
from pianobot.physics.trajectory import Press
from pianobot.physics.world import World, WorldConfig
from pianobot.play import play_song
from pianobot.play.library import etude
from pianobot.store import load_run

SONGS = Path(__file__).resolve().parents[2] / "experiments" / "songs"

TWINKLE = SONGS / "twinkle.mid"


@pytest.fixture(scope="module")
def twinkle_results(fitted_model: LearnedPredictor, tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    data = tmp_path_factory.mktemp("twinkle")
    return {
        "model": play_song(TWINKLE, data_dir=data, model=fitted_model, seed=0),
        "naive": play_song(TWINKLE, data_dir=data, planner="naive", seed=0),
        "data": data,
    }


def test_twinkle_at_90_bpm_meets_the_targets(twinkle_results: dict[str, object]) -> None:
    result = twinkle_results["model"]
    assert read_song(TWINKLE).tempo_bpm == pytest.approx(90.0, rel=1e-6)
    score = result.score  # type: ignore[attr-defined]
    assert score.notes_target == 42
    assert score.f1 >= 0.95
    assert score.onset_rms_ms <= 20.0
    assert score.velocity_mae <= 4.0


def test_naive_planner_is_clearly_worse(twinkle_results: dict[str, object]) -> None:
    model = twinkle_results["model"].score  # type: ignore[attr-defined]
    naive = twinkle_results["naive"].score  # type: ignore[attr-defined]
    assert naive.f1 < 0.5 * model.f1
    assert naive.onset_rms_ms > 5 * model.onset_rms_ms
    assert naive.velocity_mae > 5 * model.velocity_mae


def test_the_performance_is_stored_as_a_play_run(twinkle_results: dict[str, object]) -> None:
    result = twinkle_results["model"]
    run = load_run(result.performance.run_id, twinkle_results["data"])  # type: ignore[attr-defined, arg-type]
    assert run.meta["kind"] == "play" and run.meta["status"] == "completed"
    assert len(run.plan) == 42 and len(run.trials) == 42
    assert {"target_velocity", "predicted_velocity", "onset_target_s"} <= set(run.trials.columns)
    assert (run.midi["type"] == "note_on").sum() == result.score.notes_played  # type: ignore[attr-defined]
    for name in ("performance.mid", "pianoroll.png", "score.json"):
        assert (run.path / name).is_file()
    played = read_song(run.path / "performance.mid").notes
    assert len(played) == result.score.notes_played  # type: ignore[attr-defined]
    assert (run.path / "pianoroll.png").read_bytes()[:4] == b"\x89PNG"


def test_to_dict_has_the_score_keys(twinkle_results: dict[str, object]) -> None:
    payload = twinkle_results["model"].to_dict()  # type: ignore[attr-defined]
    for key in ("f1", "onset_rms_ms", "onset_mean_ms", "duration_mae_ms", "velocity_mae",
                "notes_target", "notes_played", "velocity_mae_unmapped", "mapping"):
        assert key in payload
    assert payload["velocity_mae_unmapped"] > payload["velocity_mae"]  # the finger is soft


def _changed_world() -> World:
    """The default world with a 30 % more sensitive velocity curve and a 30 % stiffer finger."""
    base = World.default(0).model
    msd = MSDParams()
    config = WorldConfig(
        piano={"full_scale_speed_mps": base.piano.full_scale_speed_mps / 1.3},
        msd={"k1_a_npm": 1.3 * msd.k1_a_npm, "k1_b_npm_per_kpa": 1.3 * msd.k1_b_npm_per_kpa},
    )
    return World(config, 0)


def test_adaptation_converges_on_a_different_world(fitted_model: LearnedPredictor, tmp_path: Path) -> None:
    spec = etude(60)
    song = write_song(tmp_path / "etude.mid", spec.to_notes(), tempo_bpm=spec.tempo_bpm)
    world = _changed_world()
    # The planner's model was fitted on the default world: at the loudest stroke it predicts a
    # velocity far from what the changed world's piano reports for the same press.
    table_speed = 0.06
    predicted = float(fitted_model.predict(pd.DataFrame({
        "down_velocity_mps": [table_speed], "vacuum_kpa": [-80.0], "hold_s": [0.0]}))["on_velocity"].iloc[0])
    actual = world.keystroke(Press(0.002, 0.025, table_speed, 0.2, 2.0), -80.0, note=60, key="probe").on_velocity
    assert actual is not None and abs(actual - predicted) > 0.3 * predicted
    fixed = play_song(song, data_dir=tmp_path, model=fitted_model, world=world, seed=0).score
    adapted_result = play_song(song, data_dir=tmp_path, model=fitted_model, world=world, seed=0, adapt=True)
    adapted = adapted_result.score
    assert fixed is not None and adapted is not None
    first, last = adapted.velocity_mae_between(0, 20), adapted.velocity_mae_between(40, 60)
    assert last <= 0.5 * first
    assert last < fixed.velocity_mae_between(40, 60)
    history = adapted_result.performance.adaptation  # type: ignore[union-attr]
    assert len(history) == 60 and history[-1]["velocity_gain"] != 1.0
    assert (adapted_result.performance.run_path / "adaptation.parquet").is_file()  # type: ignore[union-attr]


def test_standard_notation_reports_the_notes_it_cannot_play(fitted_model: LearnedPredictor, tmp_path: Path) -> None:
    result = play_song(SONGS / "twinkle_standard.mid", data_dir=tmp_path, model=fitted_model, dry_run=True)
    skipped = result.plan.notes[result.plan.notes["status"] == "skip"]
    assert 0 < len(skipped) < 42
    assert skipped["reason"].str.contains("no time to release and re-strike").all()
    assert any("cannot be played in time" in w for w in result.warnings)
    assert result.performance is None and not (tmp_path / "runs").exists()


def test_chords_play_the_melody_with_a_warning(fitted_model: LearnedPredictor, tmp_path: Path) -> None:
    beat = 60 / 90 * 4
    notes = [Note(60, 0.0, 2.0, 60), Note(64, 0.0, 2.0, 70), Note(67, 0.0, 2.0, 80),
             Note(65, beat, beat + 2.0, 90), Note(57, beat, beat + 2.0, 40)]
    song = write_song(tmp_path / "chords.mid", notes, tempo_bpm=90)
    result = play_song(song, data_dir=tmp_path, model=fitted_model, seed=0)
    assert [n.pitch for n in result.melody.notes] == [67, 65]
    assert any("chord" in w for w in result.warnings)
    assert result.score is not None and result.score.notes_target == 2 and result.score.f1 == 1.0


def test_dynamics_modes_and_bad_options(fitted_model: LearnedPredictor, tmp_path: Path) -> None:
    mapped = play_song(TWINKLE, data_dir=tmp_path, model=fitted_model, dry_run=True).plan
    absolute = play_song(TWINKLE, data_dir=tmp_path, model=fitted_model, dry_run=True, dynamics="absolute").plan
    assert mapped.dynamics is not None and absolute.dynamics is not None
    lo, hi = mapped.dynamics.target_range
    targets = mapped.notes["target_velocity"].to_numpy(float)
    assert targets.min() == pytest.approx(lo) and targets.max() == pytest.approx(hi)
    assert np.all(absolute.notes["target_velocity"].to_numpy(float) == hi)  # 40–110 all above the reach
    with pytest.raises(InputError, match="planner"):
        play_song(TWINKLE, data_dir=tmp_path, planner="fancy", dry_run=True)
    with pytest.raises(InputError, match="naive"):
        play_song(TWINKLE, data_dir=tmp_path, planner="naive", adapt=True, dry_run=True)


def test_a_song_without_playable_notes_is_refused(tmp_path: Path) -> None:
    song = write_song(tmp_path / "high.mid", [Note(100, 0.0, 1.0, 64)], tempo_bpm=90)
    with pytest.raises(InputError, match="no playable notes"):
        play_song(song, data_dir=tmp_path, transpose=12, dry_run=True)
