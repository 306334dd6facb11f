"""Logs from the independent truth lab (`tests/truth`: its own arm, finger-key physics, piano
readout and read(2) FIFO): every keystroke's MIDI outcome must come back on its own line."""

from __future__ import annotations

from pathlib import Path

import pytest

from pianobot.io.keystroke_log import read_keystroke_log
from tests.truth import materialise, scenario


@pytest.mark.parametrize("name", ["midi-clean-stiff-key-1", "midi-key_preload-felt_rail-strong"])
def test_truth_lab_logs_import_exactly(tmp_path: Path, name: str) -> None:
    made = materialise(scenario(name), tmp_path)
    trials = read_keystroke_log(made.data_file).trials
    truth = made.truth["strokes"]
    assert len(trials) == len(truth)
    for row, stroke in zip(trials.itertuples(), truth, strict=True):
        if stroke["on_velocity"] is None:
            assert row.status == "silent", row.source_line
        else:
            assert row.status == "ok", row.source_line
            assert (row.on_velocity, row.n_note_on) == (stroke["on_velocity"], stroke["n_note_on"])
    sounded = made.truth["outcome"]["sounded"]
    assert (trials["status"] == "ok").sum() == sounded and trials["assignment"].isin(["own line", "silent"]).all()
