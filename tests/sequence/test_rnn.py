"""The optional recurrent model: compared on the same grouped folds; without PyTorch, one line."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from pianobot.analysis.sequence.evaluate import cross_validate_sequence
from pianobot.analysis.sequence.strokes import stroke_sequences
from tests.cli_runner import invoke_cli
from tests.sequence.seq_truth import make_trials


def test_without_pytorch_the_rnn_says_how_to_install_it_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setitem(sys.modules, "torch", None)  # import torch now raises ImportError
    code, out, err = invoke_cli(["fit", "anyrun", "--data", str(tmp_path), "--model", "sequence", "--model", "rnn"],
                                capsys, monkeypatch)
    assert code == 2 and out == ""
    assert err.strip().count("\n") == 0 and "pip install 'pianobot[rnn]'" in err


def test_the_rnn_learns_the_context_the_per_stroke_model_cannot_see() -> None:
    pytest.importorskip("torch")
    table = stroke_sequences(make_trials(48, 10, seed=5))
    cv = cross_validate_sequence(table, ks=(0,), per_note=(), folds=3, workers=1, rnn=True).set_index("model")
    assert list(cv.index) == ["sequence k=0", "rnn gru"]
    # Each sequence's hidden finger state shows in its strokes: the GRU carries it, k = 0 cannot.
    assert cv.loc["rnn gru", "on_velocity_rmse"] < 0.85 * cv.loc["sequence k=0", "on_velocity_rmse"]
