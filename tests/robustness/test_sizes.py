"""Input sizes are bounded before anything is allocated, with the size and its cost in words."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from pianobot.plan import count_trials, expand
from pianobot.spec import load_spec
from robustness.harness import assert_cli_refused

GRID = """\
name: big
finger: soft
sweep:
  mode: grid
  params:
    vacuum_kpa: {{start: -80, stop: 0, num: {n}}}
    down_velocity_mps: {{start: 0.01, stop: 0.06, num: {n}}}
    acceleration_mps2: {{start: 0.1, stop: 2.0, num: {n}}}
    depth_m: {{start: 0.02, stop: 0.035, num: {n}}}
"""


@pytest.mark.parametrize(("num", "count"), [(178, "1,003,875,856"), (57, "10,556,001")])
@pytest.mark.parametrize("dry_run", [False, True], ids=["sweep", "dry-run"])
def test_a_huge_grid_is_refused_with_its_count_and_lab_time(
    num: int, count: str, dry_run: bool, completed_run: Path, tmp_path: Path,
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    spec = tmp_path / "big.yaml"
    spec.write_text(GRID.format(n=num))
    line = assert_cli_refused(["sweep", spec, "--data", completed_run, *(["--dry-run"] if dry_run else [])],
                   completed_run, capsys, monkeypatch, f"plans {count} trials", "of lab time",
                   "limit of 200,000", "--max-trials")
    assert "years" in line or "days" in line


def test_the_limit_is_configurable(completed_run: Path, tmp_path: Path,
                                   capsys: pytest.CaptureFixture[str],
                                   monkeypatch: pytest.MonkeyPatch) -> None:
    spec = tmp_path / "grid.yaml"
    spec.write_text(GRID.format(n=3))  # 81 trials
    assert_cli_refused(["sweep", spec, "--max-trials", "80", "--data", completed_run], completed_run, capsys,
            monkeypatch, "plans 81 trials", "limit of 80")


def test_counting_never_expands_and_expansion_matches_the_count() -> None:
    from pianobot.spec import ExperimentSpec

    spec = ExperimentSpec.model_validate({
        "name": "x", "finger": "soft",
        "sweep": {"mode": "grid", "repeats": 3, "order": "blocked-shuffle",
                  "params": {"vacuum_kpa": [0, -40], "down_velocity_mps": {"start": 0.01, "stop": 0.05, "num": 5},
                             "depth_m": [0.02, 0.03]}},
    })
    assert count_trials(spec) == 60 == len(expand(spec))
    huge = spec.model_copy(update={"sweep": spec.sweep.model_copy(update={"repeats": 10**6})})
    assert count_trials(huge) == 2 * 10**7  # a Python int: no overflow, no allocation


def test_the_study_grid_is_within_the_default_limit() -> None:
    spec = load_spec(Path(__file__).resolve().parents[2] / "experiments" / "soft_finger_grid.yaml",
                     rig=Path(__file__).resolve().parents[2] / "experiments" / "rigs" / "sim-extended.yaml")
    assert count_trials(spec) == 2025


def test_a_keystroke_log_beyond_the_line_limit_is_refused_before_parsing(
    completed_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import pianobot.io.keystroke_log as keystroke_log

    monkeypatch.setattr(keystroke_log, "MAX_LOG_LINES", 1000)  # the real limit is 10⁶ lines
    log = tmp_path / "huge.txt"
    log.write_text("{'control': [60, 45, 0.5, 0.03, 0.04, 0.05, 0], 'midi': []}\n" * 1001)
    assert_cli_refused(["import", "keystroke-log", log, "--data", completed_run], completed_run, capsys,
            monkeypatch, "has more than 1,000 lines", "split it into sessions")


def _song(n_notes: int) -> bytes:
    def varlen(n: int) -> bytes:
        out = [n & 0x7F]
        n >>= 7
        while n:
            out.append((n & 0x7F) | 0x80)
            n >>= 7
        return bytes(reversed(out))

    events = bytearray()
    for k in range(n_notes):
        events += varlen(0) + bytes([0x90, 60 + k % 12, 64]) + varlen(10) + bytes([0x80, 60 + k % 12, 0])
    events += varlen(0) + b"\xff\x2f\x00"
    return (b"MThd" + struct.pack(">IHHH", 6, 0, 1, 480)
            + b"MTrk" + struct.pack(">I", len(events)) + bytes(events))


def test_a_song_beyond_the_note_limit_is_refused(completed_run: Path, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str],
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    import pianobot.io.midifile as midifile

    monkeypatch.setattr(midifile, "MAX_SONG_NOTES", 500)  # the real limit is 100,000 notes
    song = tmp_path / "long.mid"
    song.write_bytes(_song(501))
    assert_cli_refused(["play", song, "--dry-run", "--data", completed_run], completed_run, capsys, monkeypatch,
            "has 501 notes", "up to 500 notes")
