"""The dry run's feasible tempo against a brute-force search over tempos with the same model.

The dry run computes the fastest feasible tempo in one pass over the notes (per-note limits from
the stroke model and the travel times). The brute force plans the song at tempo after tempo from
the written one down — in 1 bpm steps, then in 0.1 bpm steps below the last tempo that failed —
as a user asking for that tempo would get it, and keeps the fastest at which every note is
played on time, within the loudness tolerance.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from pianobot.play import PlaySettings, TempoRequest, play_rig, play_song
from pianobot.play.session import starting_model
from pianobot.play.song_plan import LOUDER_TEXT, plan_model
from pianobot.play.strokes import stroke_tables

SONGS = Path(__file__).resolve().parents[2] / "experiments" / "songs"
RIGID = Path(__file__).resolve().parents[2] / "experiments" / "rigs" / "sim-rigid.yaml"
STEP_BPM = 0.1


def _clean(frame: object) -> bool:
    notes = frame  # a plan's notes table
    return bool((notes["status"] == "play").all() and (notes["late_s"] == 0).all()  # type: ignore[index]
                and not notes["reason"].str.contains(LOUDER_TEXT).any())  # type: ignore[index]


@pytest.mark.parametrize(("song", "rig", "finger"), [
    ("twinkle", "sim", "soft"), ("ode", "sim", "soft"), ("march", "sim", "soft"), ("waltz", str(RIGID), "rigid"),
])
def test_the_dry_run_tempo_is_the_fastest_a_brute_force_search_finds(
        song: str, rig: str, finger: str, song_files: dict[str, Path], tmp_path: Path) -> None:
    path = SONGS / "twinkle.mid" if song == "twinkle" else song_files[song]
    dry = play_song(path, data_dir=tmp_path, dry_run=True, rig=rig, finger=finger)
    tempo, geometry = dry.plan.tempo, dry.plan.geometry
    assert tempo is not None and geometry is not None and dry.performance is None
    settings = PlaySettings(finger=finger)  # type: ignore[arg-type]
    rig_spec = play_rig(rig)
    predictor = starting_model(None, finger)[0]  # type: ignore[arg-type]
    tables = stroke_tables(predictor, settings, rig_spec, geometry, levels=sorted(dry.plan.tables))
    notes = list(dry.melody.notes)
    written = tempo.written_bpm

    def clean_at(bpm: float) -> bool:
        return _clean(plan_model(notes, predictor, settings, rig_spec, tables=tables, written_bpm=written,
                                 tempo=TempoRequest("bpm", bpm, True)).notes)

    coarse = next(b for b in np.arange(written, 0.5, -1.0) if clean_at(float(b)))
    fine = [b for b in np.arange(min(written, coarse + 1.0), coarse - 1e-9, -STEP_BPM) if clean_at(float(b))]
    fastest = float(fine[0])
    print(f"{song} ({finger}): dry run {tempo.played_bpm:g} bpm (feasible {tempo.feasible_bpm:.3f}), "
          f"brute force {fastest:g} bpm")
    assert tempo.played_bpm == pytest.approx(min(written, math.floor(tempo.feasible_bpm * 10) / 10), abs=1e-9)
    assert abs(fastest - min(written, tempo.feasible_bpm)) <= STEP_BPM + 1e-6
    # Slower is never worse: a few tempos below the limit are clean too.
    for bpm in np.linspace(0.5 * fastest, fastest, 4):
        plan = plan_model(notes, predictor, settings, rig_spec, tables=tables, written_bpm=written,
                          tempo=TempoRequest("bpm", float(bpm), True))
        assert _clean(plan.notes)


def test_a_few_notes_that_slow_a_whole_song_are_named_with_the_tempo_the_rest_allow() -> None:
    from pianobot.play.tempo import Feasibility, TempoRequest, choose_tempo

    # 40 notes at 100 bpm: 38 allow 60 bpm or more, one grace note holds everything to 3 bpm.
    limits = np.full(40, 60.0)
    limits[0], limits[7], limits[8] = math.inf, 3.0, 45.0
    choice = choose_tempo(TempoRequest(), Feasibility(100.0, limits))
    assert choice.played_bpm == 3.0 and choice.few == (1, 45.0)
    message = choice.message()
    assert message is not None and "1 note(s) alone hold it below 45 bpm" in message and "--tempo 45" in message
    # Named as a musician counts notes (the eighth note is index 7); data keep the index.
    assert choice.limiting_notes[0] == 7 and "limited by note(s) 8, " in message
    # Half the notes slow it (a trill): not "a few", nothing extra said.
    limits[1::2] = 3.0
    trill = choose_tempo(TempoRequest(), Feasibility(100.0, limits))
    assert trill.few is None and "alone hold it" not in (trill.message() or "")
    # A song the finger plays at its written tempo says nothing at all.
    assert choose_tempo(TempoRequest(), Feasibility(100.0, np.full(10, 120.0))).message() is None
