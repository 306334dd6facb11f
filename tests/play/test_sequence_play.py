"""`play --model SEQMODEL`: each note planned with the notes before it, gated by the model's own CV.

The sequence model here is learned from a world written in this file (not pianobot's physics):
loudness rises with the down velocity along a saturating curve, and a key struck again right
after it was played is still rising, which takes `REPEAT_LOSS` MIDI steps off the stroke.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pianobot.analysis.sequence.evaluate import cross_validate_sequence
from pianobot.analysis.sequence.files import save_sequence_model
from pianobot.analysis.sequence.model import SequenceModel
from pianobot.analysis.sequence.strokes import stroke_sequences
from pianobot.io.midifile import Note, write_song
from pianobot.play import play_song
from pianobot.play.context import SongContext
from pianobot.store import load_run
from tests.cli_runner import invoke_cli

REPEAT_LOSS = 4.0


def _repeat_world(n_sequences: int, length: int, seed: int = 0) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    n = n_sequences * length
    notes = rng.choice([60, 62, 64], size=n)
    speed = rng.uniform(0.004, 0.06, n)
    velocity = 14.0 * (1.0 - np.exp(-speed / 0.03)) + 1.0
    order = np.tile(np.arange(length), n_sequences)
    repeat = (order > 0) & (notes == np.r_[-1, notes[:-1]])
    velocity = np.maximum(velocity - REPEAT_LOSS * repeat + rng.normal(0.0, 0.3, n), 1.0)
    return pd.DataFrame({
        "run_id": "repeat-world", "index": np.arange(n), "status": "ok",
        "sequence_id": np.repeat(np.arange(n_sequences), length), "sequence_order": order,
        "note": notes, "down_velocity_mps": speed, "up_velocity_mps": 0.7, "hold_s": rng.uniform(0.0, 0.5, n),
        "on_velocity": np.round(velocity), "midi_hold_s": 0.1, "t_on_s": 0.02 / speed + 0.1,
    })


@pytest.fixture(scope="module")
def sequence_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    table = stroke_sequences(_repeat_world(60, 10))
    cv = cross_validate_sequence(table, ks=(0, 1), per_note=(), folds=3, workers=1)
    folder = tmp_path_factory.mktemp("sequence")
    return save_sequence_model(SequenceModel(1).fit(table), folder / "repeats.json", cv=cv, runs=["repeat-world"])


@pytest.fixture(scope="module")
def repeats_song(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Pairs of repeated notes between moves, mid-loud between a quiet first and a loud last note."""
    pitches = [60, 60, 64, 64, 62, 62, 60, 64, 64, 62]
    velocities = [20, 60, 60, 60, 60, 60, 60, 60, 60, 110]
    notes = [Note(p, 3.0 * i, 3.0 * i + 0.5, v) for i, (p, v) in enumerate(zip(pitches, velocities, strict=True))]
    return write_song(tmp_path_factory.mktemp("song") / "repeats.mid", notes, tempo_bpm=60.0)


def test_repeated_notes_are_aimed_louder_where_the_context_takes_loudness_away(
    sequence_file: Path, repeats_song: Path, tmp_path: Path,
) -> None:
    context = SongContext.load(sequence_file)
    assert "on_velocity" in context.used and context.gains["on_velocity"] < -0.1
    alone = play_song(repeats_song, data_dir=tmp_path, dry_run=True, tempo="written").plan.notes
    played = play_song(repeats_song, data_dir=tmp_path, model=sequence_file, dry_run=True, tempo="written")
    plan = played.plan.notes
    repeat = (plan["pitch"] == plan["pitch"].shift(1)).to_numpy()
    effect = plan["context_velocity"].to_numpy(float)
    # Against the context-free model (which averages over repeats and moves), a repeat is
    # quieter and a move louder: the difference is the world's loss.
    assert np.all(effect[repeat] < 0) and np.all(effect[~repeat] > 0)
    assert effect[repeat].mean() - effect[~repeat].mean() < -0.6 * REPEAT_LOSS
    speed, speed0 = plan["down_velocity_mps"].to_numpy(float), alone["down_velocity_mps"].to_numpy(float)
    mid = ~repeat & (np.arange(len(plan)) > 0) & (np.arange(len(plan)) < len(plan) - 1)
    assert np.all(speed[repeat] > speed0[repeat]) and np.all(speed[mid] < speed0[mid])
    # The loudness it expects, context included, is still the target (the first note's lies
    # below the reachable range once the context is counted).
    inner = repeat | mid
    assert np.all(np.abs(plan["predicted_velocity"] - plan["target_velocity"])[inner] < 1.5)
    assert "on-velocity" in (played.plan.context or "") and "sequence model" in played.model


def test_after_a_warm_up_that_moved_from_key_to_key_only_the_repeats_are_corrected(sequence_file: Path) -> None:
    """The per-note maps come from the warm-up; their loudness already holds the warm-up's
    context (a move before every stroke), so a moved-to note needs no correction and a repeat
    needs the whole loss, not its difference to the training mix of moves and repeats."""
    model = SongContext.load(sequence_file).model
    pitches = [60, 60, 64, 64, 62, 62, 60, 64, 64, 62, 60, 62]
    plan = pd.DataFrame({"note": pitches, "down_velocity_mps": 0.03, "up_velocity_mps": 0.7, "hold_s": 0.2})
    warm_up = pd.DataFrame({"note": [60, 62, 64] * 8, "down_velocity_mps": np.geomspace(0.005, 0.06, 24),
                            "up_velocity_mps": 0.7, "hold_s": [0.0, 0.3] * 12, "status": "ok"})
    repeat = np.r_[False, np.diff(pitches) == 0]
    mixed = model.planned_effect(plan)["on_velocity"].to_numpy(float)
    moved = model.planned_effect(plan, warm_up)["on_velocity"].to_numpy(float)
    assert mixed[~repeat][1:].mean() > 0.3  # against the training mix, a move looks loud
    assert abs(moved[~repeat][1:].mean()) < 0.15 * REPEAT_LOSS
    assert moved[repeat].mean() < -0.7 * REPEAT_LOSS
    context = SongContext.load(sequence_file)
    assert context.calibrated_on(warm_up).reference is not None and context.reference is None


@pytest.mark.parametrize("gains, better", [
    ({"on_velocity": 0.01}, {}),  # context did not cut the error against no context
    ({"on_velocity": -0.3}, {"on_velocity": False}),  # it did, but stayed above the per-note model's
])
def test_a_context_that_did_not_help_on_held_out_sequences_leaves_the_plan_as_it_was(
    sequence_file: Path, repeats_song: Path, tmp_path: Path, gains: dict[str, float], better: dict[str, bool],
) -> None:
    useless = SongContext(SongContext.load(sequence_file).model, "useless", gains, better)
    said: list[str] = []
    alone = play_song(repeats_song, data_dir=tmp_path, dry_run=True, tempo="written").plan.notes
    plan = play_song(repeats_song, data_dir=tmp_path, model=useless, dry_run=True, tempo="written",
                     on_warning=said.append).plan.notes
    pd.testing.assert_frame_equal(plan, alone)
    assert any("every note is planned alone" in line for line in said)


def test_play_with_a_sequence_model_then_feed_the_performance_back(
    sequence_file: Path, repeats_song: Path, tmp_path: Path,
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    data = tmp_path / "data"
    pitches = [60, 60, 64, 64, 62, 62, 60, 64] * 3
    song = write_song(tmp_path / "longer.mid", [Note(p, 2.5 * i, 2.5 * i + 0.4, 40 + 3 * i) for i, p in enumerate(pitches)],
                      tempo_bpm=60.0)
    code, out, err = invoke_cli(["play", str(song), "--data", str(data), "--model", str(sequence_file),
                                 "--warmup", "24", "--seed", "1", "--json"], capsys, monkeypatch)
    assert code == 0, err
    payload = json.loads(out)
    assert payload["f1"] > 0.8 and "on-velocity" in payload["plan"]["context"]
    trials = load_run(payload["run_id"], data).trials
    assert (trials["phase"] == "song").sum() == len(pitches)
    # Fed back: the performance (warm-up and song) is sequences for `fit --model sequence`.
    code, out, err = invoke_cli(["fit", payload["run_id"], "--data", str(data), "--model", "sequence", "--context",
                                 "0,1", "--folds", "2", "--out-dir", str(tmp_path / "again"), "--json"],
                                capsys, monkeypatch)
    assert code == 0, err
    again = json.loads(out)
    assert again["n_strokes"] == len(trials) and again["n_sequences"] >= 3
    assert SongContext.load(Path(again["saved"])).model.n_strokes_ == len(trials)


@pytest.mark.parametrize("extra", [["--planner", "naive"], ["--adapt"]])
def test_a_sequence_model_with_the_naive_planner_or_adapt_is_one_line_and_exit_2(
    sequence_file: Path, repeats_song: Path, tmp_path: Path, extra: list[str],
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    code, _, err = invoke_cli(["play", str(repeats_song), "--data", str(tmp_path), "--model", str(sequence_file),
                               "--dry-run", *extra], capsys, monkeypatch)
    assert code == 2 and err.strip().count("\n") == 0 and extra[0] in err
