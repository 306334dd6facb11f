"""A model fitted from a sim sweep (the calibration spec), shared by the play tests."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

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
