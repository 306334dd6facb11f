"""`pianobot play`: one-line errors with exit 2, JSON score keys, dry-run plan."""

from __future__ import annotations

import json
from pathlib import Path

import mido
import pytest
from cli_runner import invoke_cli as cli

from pianobot.io.midifile import Note, write_song

SONGS = Path(__file__).resolve().parents[2] / "experiments" / "songs"
PLAY_RIG = Path(__file__).resolve().parents[2] / "experiments" / "rigs" / "sim-play.yaml"


def _type2(path: Path) -> Path:
    mid = mido.MidiFile(type=2)
    for note in (60, 62):
        track = mido.MidiTrack([mido.Message("note_on", note=note, velocity=64, time=0),
                                mido.Message("note_off", note=note, velocity=0, time=480)])
        mid.tracks.append(track)
    mid.save(path)
    return path


@pytest.mark.parametrize("kind", ["missing", "not-midi", "type-2", "no-playable-notes"])
def test_bad_input_is_one_line_and_exit_2(kind: str, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    data = tmp_path / "data"
    extra: list[str] = []
    if kind == "missing":
        song = tmp_path / "nope.mid"
    elif kind == "not-midi":
        song = tmp_path / "text.mid"
        song.write_text("MThd? no, just text\n")
    elif kind == "type-2":
        song = _type2(tmp_path / "t2.mid")
    else:
        song = write_song(tmp_path / "high.mid", [Note(105, 0.0, 1.0, 64)], tempo_bpm=90)
        extra = ["--transpose", "12"]
    code, out, err = cli(["play", str(song), "--data", str(data), "--json", *extra], capsys, monkeypatch)
    assert code == 2
    assert out == ""
    lines = [line for line in err.splitlines() if not line.startswith("warning:")]
    assert len(lines) == 1 and lines[0].startswith("error: ")
    assert "Traceback" not in err
    assert not (data / "runs").exists()


def test_naive_play_prints_the_score_keys(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    code, out, _ = cli(["play", str(SONGS / "scale_crescendo.mid"), "--planner", "naive", "--data",
                        str(tmp_path), "--json", "--plot", str(tmp_path / "roll.png")], capsys, monkeypatch)
    assert code == 0
    payload = json.loads(out)
    for key in ("f1", "onset_rms_ms", "onset_mean_ms", "duration_mae_ms", "velocity_mae",
                "notes_target", "notes_played"):
        assert key in payload
    assert payload["notes_target"] == 15 and payload["planner"] == "naive"
    assert (tmp_path / "roll.png").is_file()
    assert Path(payload["files"]["performance_mid"]).is_file()


def test_dry_run_prints_the_feasible_tempo_and_the_limiting_notes(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    code, out, err = cli(["play", str(SONGS / "twinkle.mid"), "--dry-run", "--json", "--data", str(tmp_path)],
                         capsys, monkeypatch)
    assert code == 0
    payload = json.loads(out)
    assert len(payload["plan_notes"]) == 42
    assert payload["mapping"].startswith("linear 40–110")
    tempo = payload["tempo"]
    assert tempo["request"] == "auto" and tempo["played_bpm"] < tempo["written_bpm"]
    assert tempo["played_bpm"] <= tempo["feasible_bpm"] and len(tempo["limiting_notes"]) == 3
    assert payload["plan"]["skipped"] == 0
    # One line says the written tempo is too fast and what is played instead; one that a warm-up comes.
    too_fast = [line for line in err.splitlines() if "too fast for this finger" in line]
    assert len(too_fast) == 1 and f"{tempo['played_bpm']:.4g} bpm" in too_fast[0]
    assert any("warm-up" in line for line in err.splitlines())
    code, out, _ = cli(["play", str(SONGS / "mary.mid"), "--dry-run", "--data", str(tmp_path)], capsys, monkeypatch)
    assert code == 0 and "mapping:" in out and "fastest feasible" in out and "limiting notes" in out
    firsts = [line.split()[0] for line in out.splitlines() if line.split() and line.split()[0].isdigit()]
    assert firsts[0] == "1" and "0" not in firsts  # the table counts notes from 1, as the messages do
    # At the written tempo, asked for: notes are skipped and reported, nothing is slowed down.
    code, out, err = cli(["play", str(SONGS / "twinkle.mid"), "--dry-run", "--json", "--tempo", "written",
                          "--data", str(tmp_path)], capsys, monkeypatch)
    assert code == 0
    written = json.loads(out)
    assert written["tempo"]["played_bpm"] == pytest.approx(written["tempo"]["written_bpm"])
    assert written["plan"]["skipped"] > 0 and "cannot be played in time" in err
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize(("args", "where"), [
    (["--tempo", "fast"], "--tempo"), (["--tempo", "0"], "--tempo"), (["--finger", "steel"], "--finger"),
    (["--warmup", "5", "--no-warmup"], "--no-warmup"), (["--warmup", "500"], "--warmup"),
    (["--warmup", "2"], "--warmup"),  # a level is learnt from 3 sounded notes: 2 could never work
    (["--seed", "-1"], "--seed"), (["--plot", "roll.txt"], "--plot"),  # both used to fail after the song
    (["--tempo", "30", "--tempo-scale", "0.5"], "--tempo-scale"),  # the scale was ignored silently
])
def test_bad_play_options_are_one_line_and_exit_2(args: list[str], where: str, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str],
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    code, out, err = cli(["play", str(SONGS / "mary.mid"), "--dry-run", "--data", str(tmp_path), *args],
                         capsys, monkeypatch)
    lines = [line for line in err.splitlines() if not line.startswith("warning:")]
    assert code == 2 and out == "" and len(lines) == 1 and where in lines[0]


def test_play_prints_the_score_the_tempo_and_the_warm_up(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    from pianobot.rig.station import Rig

    # What the rig finds when it opens (a UR's speed slider below 100 %) is said before the song.
    monkeypatch.setattr(Rig, "warnings", property(lambda self: ("speed slider at 50 %",)))
    code, out, err = cli(["play", str(SONGS / "scale_crescendo.mid"), "--data", str(tmp_path), "--warmup", "8"],
                         capsys, monkeypatch)
    assert code == 0
    assert "warm-up: 8 keystrokes" in out and "playing at" in out and "f1" in out
    assert "too fast for this finger" in err
    assert err.splitlines()[0] == "warning: rig: speed slider at 50 %"
    assert "report written to" in out
    run = json.loads(next((tmp_path / "runs").glob("*/run.json")).read_text())
    assert run["rig"]["warnings"] == ["speed slider at 50 %"]


def test_a_play_the_rig_stops_is_one_line_naming_the_kept_run(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    # A protective stop in the warm-up used to end in a traceback (the song's own stops are
    # handled note by note); now one line names the stop and the run that keeps what was played.
    from pianobot.rig.errors import SafetyStop
    from pianobot.rig.station import Rig

    calls = {"n": 0}
    real = Rig.press_at

    def stops_on_the_third(self: Rig, *args: object, **kwargs: object) -> object:
        calls["n"] += 1
        if calls["n"] == 3:
            raise SafetyStop("protective stop (test)")
        return real(self, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(Rig, "press_at", stops_on_the_third)
    code, out, err = cli(["play", str(SONGS / "mary.mid"), "--data", str(tmp_path), "--warmup", "4"],
                         capsys, monkeypatch)
    errors = [line for line in err.splitlines() if line.startswith("error:")]
    run = json.loads(next((tmp_path / "runs").glob("*/run.json")).read_text())
    assert code == 1 and len(errors) == 1 and "Traceback" not in err
    assert "protective stop (test)" in errors[0] and run["run_id"] in errors[0]
    assert run["status"] == "failed"


def test_counts_read_as_whole_numbers_and_json_has_no_infinity() -> None:
    from pianobot.cli.common import _clean
    from pianobot.cli.play import _fmt

    assert _fmt(3012) == "3012" and _fmt(3.5) == "3.5" and _fmt(float("nan")) == "-"  # not "3.01e+03"
    assert _clean({"hi": float("inf"), "lo": float("-inf"), "x": [float("nan"), 1.0]}) == {
        "hi": None, "lo": None, "x": [None, 1.0]}
