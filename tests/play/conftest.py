"""Shared by the play tests: a model fitted from a sim sweep, the test songs, the world's truth."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from play_reference import TruthTable, strokes, truth_table

from pianobot.analysis.learn.training import LearnedPredictor, training_set
from pianobot.run import run_sweep
from pianobot.store import load_run

REPO = Path(__file__).resolve().parents[2]
CALIBRATION = REPO / "experiments" / "play_calibration.yaml"


@pytest.fixture(scope="session")
def fitted_model(tmp_path_factory: pytest.TempPathFactory) -> LearnedPredictor:
    """A GP predictor learned from the play calibration sweep on the default sim world (seed 0)."""
    data = tmp_path_factory.mktemp("calibration")
    outcome = run_sweep(CALIBRATION, data_dir=data, progress=False)
    assert outcome.status == "completed"
    trials = load_run(outcome.run_id, data).trials
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # GP kernel bounds: harmless for this small fit
        return LearnedPredictor("gp").fit(training_set(trials))


@pytest.fixture(scope="session")
def song_files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The play test songs (built in code) written as MIDI files."""
    from pianobot.io.midifile import write_song
    from pianobot.play.library import TEST_SONGS

    folder = tmp_path_factory.mktemp("songs")
    return {name: write_song(folder / f"{name}.mid", (spec := make()).to_notes(), tempo_bpm=spec.tempo_bpm)
            for name, make in TEST_SONGS.items()}


@pytest.fixture(scope="session")
def soft_truth() -> list[TruthTable]:
    """The default world's truth for the reference tempo: every vacuum level the soft finger's
    play settings allow, every stroke shape, down velocities spread over its envelope."""
    from pianobot.physics.world import World
    from pianobot.play.settings import PlaySettings

    settings = PlaySettings()
    presses = strokes(settings.play_depth_m, np.geomspace(0.008, 0.06, 28))
    world = World.default(0)
    return [truth_table(world, level, presses) for level in settings.levels_kpa]
