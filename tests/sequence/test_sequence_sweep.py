"""The spec's sequence mode: random sequences of strokes through the normal sweep runner and store."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pianobot.analysis.learn.run import load_trials
from pianobot.analysis.sequence.strokes import stroke_sequences
from pianobot.plan import expand, plan_frame
from pianobot.spec import parse_spec_text
from tests.cli_runner import invoke_cli

SPEC = """
name: seq-test
rig: sim
finger: soft
sweep:
  mode: sequence
  sequences: {sequences}
  length: {length}
  seed: 4
  params:
    note: [60, 62, 64, 65]
    down_velocity_mps: {{low: 0.015, high: 0.06}}
    hold_s: {{low: 0.0, high: 0.4}}
    distance_m: {{low: 0.002, high: 0.01}}
  fixed:
    vacuum_kpa: -60
    depth_m: 0.025
    acceleration_mps2: 1.5
    up_velocity_mps: 0.7
{extra}
record: [midi]
"""


def _spec(sequences: int = 5, length: int = 6, extra: str = "") -> str:
    return SPEC.format(sequences=sequences, length=length, extra=extra)


def test_sequences_are_drawn_per_stroke_and_numbered_in_play_order() -> None:
    trials = expand(parse_spec_text(_spec(), "seq.yaml"))
    assert len(trials) == 30
    assert [(t.sequence_id, t.sequence_order) for t in trials[:8]] == [  # type: ignore[attr-defined]
        (0, 0), (0, 1), (0, 2), (0, 3), (0, 4), (0, 5), (1, 0), (1, 1)]
    assert len({t.note for t in trials}) == 4 and len({t.down_velocity_mps for t in trials}) == 30
    frame = plan_frame(trials)
    assert list(frame.columns[-2:]) == ["sequence_id", "sequence_order"]
    again = expand(parse_spec_text(_spec(), "seq.yaml"))
    assert [t.trial_id for t in again] == [t.trial_id for t in trials]


def test_a_random_sweep_plan_has_no_sequence_columns() -> None:
    text = _spec().replace("mode: sequence", "mode: random").replace("sequences: 5\n  length: 6", "samples: 30")
    frame = plan_frame(expand(parse_spec_text(text, "random.yaml")))
    assert "sequence_id" not in frame.columns


@pytest.mark.parametrize("extra, key", [("  order: shuffled", "order"), ("  repeats: 2", "repeats")])
def test_shuffling_or_repeating_a_sequence_sweep_is_refused(
    tmp_path: Path, extra: str, key: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    spec = tmp_path / "seq.yaml"
    spec.write_text(_spec(extra=extra))
    code, _, err = invoke_cli(["sweep", str(spec), "--dry-run", "--data", str(tmp_path / "data")], capsys, monkeypatch)
    assert code == 2 and err.strip().count("\n") == 0 and key in err


def test_a_sequence_sweep_on_the_sim_rig_is_what_fit_model_sequence_reads(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    spec = tmp_path / "seq.yaml"
    spec.write_text(_spec(sequences=8, length=6))
    data = tmp_path / "data"
    code, out, err = invoke_cli(["sweep", str(spec), "--data", str(data), "--json"], capsys, monkeypatch)
    assert code == 0, err
    run_id = json.loads(out)["run_id"]
    trials = load_trials([run_id], data)
    assert trials["sequence_id"].tolist() == [i // 6 for i in range(48)]
    assert trials["sequence_order"].tolist() == [i % 6 for i in range(48)]
    table = stroke_sequences(trials)
    assert table.n_sequences == 8 and table.frame["order"].max() == 5
