"""`play` end to end on the sim rig with the command a new user types (warm-up on, tempo auto).

The songs are built in code (`pianobot.play.library.TEST_SONGS`: 80–120 bpm, each with
repeated notes, an octave leap, dynamics from pp to ff and dotted rhythms). The tempo each is
played at is compared with the fastest tempo the finger can physically sustain for it, found by
brute force on the simulated world's truth (`play_reference`), which the planner never sees.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from play_reference import TruthTable, fastest_sustainable_bpm

from pianobot.errors import InputError
from pianobot.io.midifile import Note, read_song, write_song
from pianobot.physics.msd import MSDParams
from pianobot.physics.world import World, WorldConfig
from pianobot.play import PlayResult, play_rig, play_song
from pianobot.play.library import TEST_SONGS
from pianobot.store import load_run

SONGS = Path(__file__).resolve().parents[2] / "experiments" / "songs"
TWINKLE = SONGS / "twinkle.mid"
RIGID = str(Path(__file__).resolve().parents[2] / "experiments" / "rigs" / "sim-rigid.yaml")
HEARD_BEFORE_THE_SONG: list[str] = []  # ode's warnings as its song started (the defaults fixture)


@pytest.fixture(scope="module")
def defaults(song_files: dict[str, Path], tmp_path_factory: pytest.TempPathFactory) -> dict[str, PlayResult]:
    """Every test song played with the default command (built-in sim rig, seed 0)."""
    from pianobot.play.perform import Performer

    data = tmp_path_factory.mktemp("defaults")
    out = {}
    heard: list[str] = []
    play = Performer.play

    def play_noting_what_was_heard(self: Performer, *args: object, **kwargs: object) -> object:
        HEARD_BEFORE_THE_SONG.extend(heard)
        return play(self, *args, **kwargs)  # type: ignore[arg-type]

    for name, path in song_files.items():
        with pytest.MonkeyPatch.context() as patch:
            if name == "ode":
                patch.setattr(Performer, "play", play_noting_what_was_heard)
            result = play_song(path, data_dir=data, seed=0, on_warning=heard.append if name == "ode" else None)
        out[name] = result
        s, t = result.score, result.plan.tempo
        assert s is not None and t is not None
        print(f"{name}: written {t.written_bpm:g} bpm, played {t.played_bpm:g} bpm; F1 {s.f1:.3f}, "
              f"onset RMS {s.onset_rms_ms:.1f} ms, velocity MAE {s.velocity_mae:.2f}")
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name", list(TEST_SONGS))
def test_the_default_command_plays_every_test_song_well_at_a_tempo_the_finger_sustains(
        name: str, defaults: dict[str, PlayResult], soft_truth: list[TruthTable]) -> None:
    result = defaults[name]
    score, tempo = result.score, result.plan.tempo
    assert score is not None and tempo is not None and result.warmup is not None
    assert score.f1 >= 0.95
    assert score.onset_rms_ms <= 20.0
    assert score.velocity_mae <= 4.0
    assert (result.plan.notes["status"] == "play").all()
    reference = fastest_sustainable_bpm(list(result.melody.notes), tempo.written_bpm, soft_truth, play_rig("sim"))
    print(f"{name}: played {tempo.played_bpm:g} bpm, physical reference {reference.bpm:g} bpm")
    assert tempo.played_bpm >= 0.8 * reference.bpm
    assert tempo.played_bpm <= tempo.written_bpm


def test_the_written_tempo_is_too_fast_for_one_soft_finger_and_the_output_says_so(
        defaults: dict[str, PlayResult]) -> None:
    result = defaults["ode"]
    tempo = result.plan.tempo
    assert tempo is not None and tempo.played_bpm < tempo.written_bpm
    lines = [w for w in result.warnings if "too fast for this finger" in w]
    assert len(lines) == 1 and f"{tempo.played_bpm:.4g} bpm" in lines[0] and "--tempo written" in lines[0]
    assert lines[0] in HEARD_BEFORE_THE_SONG  # said before the song, not only after it
    assert tempo.limiting_notes and all(0 < i < len(result.melody.notes) for i in tempo.limiting_notes)


def test_the_play_run_holds_the_warm_up_and_the_song(defaults: dict[str, PlayResult]) -> None:
    result = defaults["waltz"]
    performance, warm = result.performance, result.warmup
    assert performance is not None and warm is not None and result.score is not None
    run = load_run(performance.run_id, performance.run_path.parents[1])
    assert run.meta["kind"] == "play" and run.meta["status"] == "completed"
    phases = run.trials["phase"].value_counts().to_dict()
    assert phases == {"warmup": 12, "song": 24}
    summary = run.meta["warmup"]
    assert summary["strokes"] == 12 and summary["lab_time_s"] == pytest.approx(warm.lab_time_s)
    assert 5.0 < summary["lab_time_s"] < 60.0  # seconds of lab time
    assert summary["lead_rmse_ms_held_out"] < 40.0
    # The planner's model is the warm-up's fit, and it says where it is trusted.
    assert set(warm.speed_ranges_mps) == {float(v) for v in result.plan.notes["vacuum_kpa"]}
    assert {"target_velocity", "predicted_velocity", "onset_target_s"} <= set(run.trials.columns)
    assert "sim-truth" in set(run.samples["source"])
    for name in ("performance.mid", "pianoroll.png", "warmup.png", "score.json", "song_plan.parquet", "report.html"):
        assert (run.path / name).is_file()
    report = (run.path / "report.html").read_text()
    for heading in ("Performance", "Tempo and plan", "Warm-up", "Notes"):
        assert f">{heading}<" in report
    assert report.count("data:image/png;base64") == 2  # the piano roll and the warm-up fit
    assert (run.path / "pianoroll.png").read_bytes()[:4] == b"\x89PNG"
    payload = json.loads((run.path / "score.json").read_text())
    assert len(payload["per_note"]) == 24
    assert {"onset_error_s", "velocity_error", "status"} <= set(payload["per_note"][0])
    assert payload["warmup"]["strokes"] == 12 and payload["plan"]["tempo"]["played_bpm"] == result.plan.tempo.played_bpm  # type: ignore[union-attr]
    assert payload["tempo_relative"]["heard_tempo_bpm"] == pytest.approx(result.plan.tempo.played_bpm, rel=0.02)  # type: ignore[union-attr]
    notes = read_song(run.path / "performance.mid").notes
    assert len(notes) == result.score.notes_played


def changed_world(seed: int = 0) -> World:
    """Another piano and finger: a 30 % more sensitive velocity curve, a 30 % stiffer finger."""
    base = World.default(seed).model
    msd = MSDParams()
    return World(WorldConfig(
        piano={"full_scale_speed_mps": base.piano.full_scale_speed_mps / 1.3},
        msd={"k1_a_npm": 1.3 * msd.k1_a_npm, "k1_b_npm_per_kpa": 1.3 * msd.k1_b_npm_per_kpa},
    ), seed)


def test_the_warm_up_learns_another_piano_and_without_it_the_song_falls_apart(
        song_files: dict[str, Path], tmp_path: Path) -> None:
    """The planner never reads the world: on a different piano and finger the warm-up is what
    keeps the song on time and in loudness; the starting model alone is late and off in loudness."""
    song = song_files["rise_and_fall"]
    warmed = play_song(song, data_dir=tmp_path, seed=1, world=changed_world(1))
    cold = play_song(song, data_dir=tmp_path, seed=1, world=changed_world(1), warmup=0)
    assert warmed.score is not None and cold.score is not None
    print(f"changed world: warm-up F1 {warmed.score.f1:.3f} onset RMS {warmed.score.onset_rms_ms:.1f} ms "
          f"velocity MAE {warmed.score.velocity_mae:.2f}; without: F1 {cold.score.f1:.3f}")
    assert warmed.score.f1 >= 0.95 and warmed.score.onset_rms_ms <= 20.0 and warmed.score.velocity_mae <= 4.0
    assert cold.score.f1 < warmed.score.f1 - 0.1
    assert cold.score.onset_rms_ms > 2 * warmed.score.onset_rms_ms
    assert cold.score.velocity_mae > 2 * warmed.score.velocity_mae
    assert cold.warmup is None and cold.to_dict()["warmup"] is None


def test_naive_planner_is_clearly_worse_at_the_same_tempo(tmp_path: Path) -> None:
    model = play_song(TWINKLE, data_dir=tmp_path, seed=0)
    assert model.plan.tempo is not None and model.score is not None
    naive = play_song(TWINKLE, data_dir=tmp_path, planner="naive", seed=0, tempo=str(model.plan.tempo.played_bpm))
    assert naive.score is not None and naive.plan.tempo is not None
    assert naive.plan.tempo.played_bpm == model.plan.tempo.played_bpm
    assert naive.score.f1 < 0.25 * model.score.f1
    assert naive.score.velocity_mae > 3 * model.score.velocity_mae


def test_at_the_written_tempo_the_notes_that_cannot_keep_up_are_skipped_and_reported(tmp_path: Path) -> None:
    result = play_song(TWINKLE, data_dir=tmp_path, tempo="written", dry_run=True)
    skipped = result.plan.notes[result.plan.notes["status"] == "skip"]
    assert result.plan.tempo is not None and result.plan.tempo.played_bpm == pytest.approx(90.0, rel=1e-6)
    assert 0 < len(skipped) < 42
    assert skipped["reason"].str.contains("no time to release and re-strike").all()
    assert any("cannot be played in time" in w for w in result.warnings)
    assert result.performance is None and not (tmp_path / "runs").exists()


def test_a_song_slow_enough_is_played_at_its_written_tempo(tmp_path: Path) -> None:
    notes = [Note(60 + 2 * (i % 3), 4.0 * i, 4.0 * i + 3.0, 40 + 10 * i) for i in range(6)]
    song = write_song(tmp_path / "slow.mid", notes, tempo_bpm=60)
    result = play_song(song, data_dir=tmp_path, seed=0, warmup=6)
    assert result.plan.tempo is not None and result.score is not None
    assert result.plan.tempo.played_bpm == 60.0 and result.plan.tempo.feasible_bpm > 60.0
    assert not any("too fast" in w for w in result.warnings)
    assert result.score.f1 == 1.0


def test_chords_play_the_melody_with_a_warning(tmp_path: Path) -> None:
    beat = 60 / 90 * 4
    notes = [Note(60, 0.0, 2.0, 60), Note(64, 0.0, 2.0, 70), Note(67, 0.0, 2.0, 80),
             Note(65, beat, beat + 2.0, 90), Note(57, beat, beat + 2.0, 40)]
    song = write_song(tmp_path / "chords.mid", notes, tempo_bpm=90)
    result = play_song(song, data_dir=tmp_path, seed=0, warmup=6)
    assert [n.pitch for n in result.melody.notes] == [67, 65]
    assert any("chord" in w for w in result.warnings)
    assert result.score is not None and result.score.notes_target == 2 and result.score.f1 == 1.0


def test_dynamics_modes_and_bad_options(tmp_path: Path) -> None:
    mapped = play_song(TWINKLE, data_dir=tmp_path, dry_run=True).plan
    absolute = play_song(TWINKLE, data_dir=tmp_path, dry_run=True, dynamics="absolute").plan
    assert mapped.dynamics is not None and absolute.dynamics is not None
    lo, hi = mapped.dynamics.target_range
    targets = mapped.notes["target_velocity"].to_numpy(float)
    assert targets.min() == pytest.approx(lo) and targets.max() == pytest.approx(hi)
    assert np.all(absolute.notes["target_velocity"].to_numpy(float) == hi)  # 40–110 all above the reach
    for kwargs, where in (({"planner": "fancy"}, "planner"), ({"planner": "naive", "adapt": True}, "naive"),
                          ({"finger": "steel"}, "finger"), ({"warmup": -1}, "warm-up"), ({"tempo": "fast"}, "tempo")):
        with pytest.raises(InputError, match=where):
            play_song(TWINKLE, data_dir=tmp_path, dry_run=True, **kwargs)  # type: ignore[arg-type]


def test_a_song_without_playable_notes_is_refused(tmp_path: Path) -> None:
    song = write_song(tmp_path / "high.mid", [Note(100, 0.0, 1.0, 64)], tempo_bpm=90)
    with pytest.raises(InputError, match="no playable notes"):
        play_song(song, data_dir=tmp_path, transpose=12, dry_run=True)


@pytest.mark.slow
@pytest.mark.parametrize(("name", "rig"), [("ode", RIGID), ("march", RIGID), ("waltz", "sim")])
def test_the_rigid_finger_plays_at_the_written_tempo_where_the_dry_run_says_it_is_feasible(
        name: str, rig: str, tmp_path: Path) -> None:
    """A user reads the dry run's feasible tempo and writes the song at it (or keeps its own
    tempo when that is feasible), then asks for the written tempo: every note is kept. On the
    built-in rig (`--finger rigid` alone) as on a rigid finger's rig file."""
    spec = TEST_SONGS[name]()
    path = write_song(tmp_path / f"{name}.mid", spec.to_notes(), tempo_bpm=spec.tempo_bpm)
    dry = play_song(path, data_dir=tmp_path, dry_run=True, rig=rig, finger="rigid")
    assert dry.plan.tempo is not None
    bpm = min(spec.tempo_bpm, float(np.floor(dry.plan.tempo.feasible_bpm)))
    scale = spec.tempo_bpm / bpm
    notes = [Note(n.pitch, n.onset_s * scale, n.offset_s * scale, n.velocity) for n in spec.to_notes()]
    at = write_song(tmp_path / f"{name}-at.mid", notes, tempo_bpm=bpm)
    assert play_song(at, data_dir=tmp_path, dry_run=True, rig=rig, finger="rigid", tempo="written").plan.summary()["skipped"] == 0
    result = play_song(at, data_dir=tmp_path, rig=rig, finger="rigid", tempo="written", seed=0)
    assert result.plan.tempo is not None and result.score is not None
    assert result.plan.tempo.played_bpm == pytest.approx(bpm, rel=1e-4)
    print(f"rigid {name} at {bpm:g} bpm: F1 {result.score.f1:.3f}, onset RMS {result.score.onset_rms_ms:.1f} ms")
    assert result.score.f1 >= 0.95


@pytest.mark.slow
def test_the_default_command_learns_a_piano_simulated_by_independent_code(
        song_files: dict[str, Path], tmp_path: Path) -> None:
    """The truth lab's finger, key and piano (`tests/truth`: its own arm, integrator, base numbers
    and two-contact readout) share nothing with `pianobot.physics`; the warm-up learns them."""
    from truth_world import TruthWorld

    result = play_song(song_files["rise_and_fall"], data_dir=tmp_path, seed=0, world=TruthWorld("stiff-key"))
    score, tempo, warm = result.score, result.plan.tempo, result.warmup
    assert score is not None and tempo is not None and warm is not None
    print(f"truth lab (stiff-key): {tempo.played_bpm:g} bpm, F1 {score.f1:.3f}, onset RMS {score.onset_rms_ms:.1f} ms, "
          f"velocity MAE {score.velocity_mae:.2f}")
    assert score.f1 >= 0.95 and score.onset_rms_ms <= 20.0 and score.velocity_mae <= 4.0
    assert tempo.played_bpm < tempo.written_bpm and (result.plan.notes["status"] == "play").all()
