"""The warm-up's design and fit on a piano written here, sharing nothing with the physics.

The synthetic piano's laws are analytic and of other forms than the simulated world's: it is
silent below a threshold speed, its loudness rises like a power of the excess speed and
saturates at a ceiling, the note-on comes after a fixed latency plus the time to push through a
fixed travel, and the note lasts a fixed release time plus a fraction of the arm's hold.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pianobot.play import PlaySettings, play_rig
from pianobot.play.geometry import StrokeGeometry
from pianobot.play.warmup import design_warmup, fit_warmup, survey_size, useful_speeds

GEOMETRY = StrokeGeometry(distance_m=0.002, depth_m=0.025, acceleration_mps2=2.0, up_velocity_mps=0.7)
THRESHOLD_MPS, CEILING = 0.016, 70.0


def piano(speed: float, hold: float) -> dict[str, float | str]:
    """What the synthetic piano reports for one stroke (a trials row's outcome columns)."""
    if speed < THRESHOLD_MPS:
        return {"status": "silent", "on_velocity": math.nan, "t_on_s": math.nan, "midi_hold_s": math.nan}
    loudness = min(CEILING, 2.0 + 9000.0 * (speed - THRESHOLD_MPS) ** 1.6)
    return {"status": "ok", "on_velocity": float(round(loudness)), "t_on_s": 0.012 + 0.0231 / speed,
            "midi_hold_s": 0.09 + 0.8 * hold}


def played(trials: list) -> pd.DataFrame:  # type: ignore[type-arg]
    return pd.DataFrame([{**t.parameters(), "trial_id": t.trial_id, **piano(t.down_velocity_mps, t.hold_s)}
                         for t in trials])


def test_the_warm_up_surveys_then_maps_where_loudness_changes_and_learns_the_piano() -> None:
    settings, rig = PlaySettings(), play_rig("sim")
    survey = design_warmup([64, 60, 64, 67], GEOMETRY, [-80.0], settings, rig, strokes_per_level=12, song_key="s")
    assert len(survey) == survey_size(12) == 4
    speeds = [t.down_velocity_mps for t in survey]
    assert speeds[0] == pytest.approx(0.01) and speeds[-1] == pytest.approx(0.06)  # the whole envelope
    assert np.allclose(np.diff(np.log(speeds)), np.log(6) / 3)  # geometric
    assert [t.note for t in survey] == [64, 60, 67, 64]  # the song's keys, the most frequent first
    first = played(survey)
    assert list(first["status"]) == ["silent", "ok", "ok", "ok"]
    lo, hi = useful_speeds(first, 0.01, 0.06)
    # From the fastest stroke as quiet as the quietest heard (slower ones are silent or no
    # quieter) to the slowest as loud as the loudest (here the envelope's fastest).
    assert (lo, hi) == pytest.approx((speeds[1], speeds[3]))
    focus = design_warmup([64, 60, 64, 67], GEOMETRY, [-80.0], settings, rig, strokes_per_level=12, song_key="s",
                          survey=first)
    assert len(focus) == 8 and {t.index for t in focus} == set(range(4, 12))
    assert min(t.down_velocity_mps for t in focus) == pytest.approx(lo)
    assert max(t.down_velocity_mps for t in focus) == pytest.approx(hi)
    assert {t.hold_s for t in focus} == {0.0, settings.warmup_hold_s}
    rows = pd.concat([first, played(focus)], ignore_index=True)
    warm = fit_warmup(rows, GEOMETRY, lab_time_s=12.0, survey=4)
    assert warm.levels_kpa == (-80.0,) and warm.speed_ranges_mps[-80.0] == pytest.approx((lo, hi))
    # The fitted maps against the piano's laws where the song will be played.
    grid = np.linspace(lo, hi, 40)
    frame = pd.DataFrame({"down_velocity_mps": grid, "hold_s": 0.2, "vacuum_kpa": -80.0, **GEOMETRY.to_dict()})
    predicted = warm.predictor.predict(frame)
    truth = pd.DataFrame([piano(v, 0.2) for v in grid])
    lead_error = (predicted["lead_s"] - truth["t_on_s"]).abs()
    assert lead_error.max() < 0.01, lead_error.max()
    assert (predicted["on_velocity"] - truth["on_velocity"]).abs().mean() < 1.5
    assert (predicted["midi_hold_s"] - truth["midi_hold_s"]).abs().max() < 0.03
    assert (predicted["p_silent"] < 0.5).all()
    below = warm.predictor.predict(frame.assign(down_velocity_mps=0.011))
    assert (below["p_silent"] >= 0.5).all()  # the silent edge is learned too
    summary = warm.summary()
    assert summary["strokes"] == 12 and summary["silent"] >= 1
    assert summary["lead_rmse_ms_held_out"] < 10.0
    assert {row for row in summary["fit"]} == {"gp", "poly", "spline"}


def test_a_warm_up_that_hears_nothing_is_a_clear_error() -> None:
    settings, rig = PlaySettings(), play_rig("sim")
    survey = design_warmup([60], GEOMETRY, [-80.0], settings, rig, strokes_per_level=6, song_key="s")
    rows = played(survey).assign(status="silent", on_velocity=math.nan, t_on_s=math.nan)
    from pianobot.play.warmup import WarmUpFailed

    with pytest.raises(WarmUpFailed, match="warm-up heard 0 note"):
        fit_warmup(rows, GEOMETRY, lab_time_s=1.0)


def test_the_lab_time_estimate_matches_the_warm_up_on_the_sim_rig(song_files: dict[str, Path], tmp_path: Path) -> None:
    from pianobot.play import play_song

    result = play_song(song_files["waltz"], data_dir=tmp_path, seed=0)
    assert result.warmup is not None and result.performance is not None
    from pianobot.store import load_run

    meta = load_run(result.performance.run_id, tmp_path).meta
    estimate = meta["warmup_planned"]["estimated_lab_time_s"]
    assert estimate == pytest.approx(result.warmup.lab_time_s, rel=0.35)
    print(f"warm-up lab time {result.warmup.lab_time_s:.1f} s, estimated {estimate:.1f} s")


def test_a_song_at_one_loudness_plays_by_default(tmp_path: Path) -> None:
    """Every note at velocity 80, as a notation program exports a score without dynamics. The
    plan puts it all at one vacuum level (63 % up the reachable loudness, 80 on 1-127); where this piano
    never sounds at that level (the default world at -40 kPa), the warm-up moves on to the level
    the plan then takes instead of giving up."""
    from pianobot.io.midifile import Note, write_song
    from pianobot.play import play_song

    notes = [Note(60 + (i % 5), 0.5 * i, 0.5 * i + 0.4, 80) for i in range(10)]
    song = write_song(tmp_path / "even.mid", notes, tempo_bpm=120)
    heard: list[str] = []
    result = play_song(song, data_dir=tmp_path / "data", seed=0, on_warning=heard.append)
    assert result.score is not None and result.performance is not None and result.warmup is not None
    assert result.score.f1 >= 0.9 and result.score.notes_played == len(notes)
    velocities = np.array([n.velocity for n in result.performance.notes], dtype=float)
    assert velocities.std() <= 2.0  # played evenly
    moved = [w for w in heard if "warm-up heard no note" in w]
    print(f"F1 {result.score.f1:.2f}, velocities {velocities.mean():.1f} ± {velocities.std():.1f}; {moved}")


def test_a_hold_map_is_not_warm_started_from_a_map_of_other_inputs() -> None:
    """A warm-up over two vacuum levels: the hold map sees (speed, vacuum, hold), the lead map it
    used to start from only (speed, vacuum); the Gaussian process raised on the mismatch."""
    from pianobot.analysis.learn.training import LearnedPredictor, training_set

    rng = np.random.default_rng(0)
    n = 24
    speed = np.geomspace(0.01, 0.06, n)
    frame = pd.DataFrame({"down_velocity_mps": np.log(speed), "vacuum_kpa": np.repeat([-60.0, -80.0], n // 2),
                          "hold_s": np.tile([0.0, 0.1], n // 2), "status": "ok",
                          "on_velocity": 200 * speed + rng.normal(0, 0.5, n), "t_on_s": 0.01 / speed,
                          "midi_hold_s": 0.2 + rng.normal(0, 0.01, n)})
    lead = LearnedPredictor("gp").fit(training_set(frame.assign(hold_s=0.0, midi_hold_s=np.nan)))
    hold = LearnedPredictor("gp").fit(training_set(frame), warm=lead)
    assert tuple(hold.inputs_) != tuple(lead.inputs_)
    assert np.isfinite(hold.predict(frame)["midi_hold_s"]).all()


@pytest.mark.parametrize(("velocities", "expected"), [
    ([math.nan, math.nan, math.nan, math.nan], (0.01, 0.5)),  # heard nothing: everything
    ([5.0, 5.0, 5.0, 5.0], (0.01, 0.5)),  # one loudness: everything
    ([3.0, 40.0, 127.0, 127.0], (0.01, 0.1357)),  # saturates: up to the first loudest
    ([math.nan, 2.0, 2.0, 90.0], (0.1357, 0.5)),  # silent, then a plateau at the quiet end
])
def test_useful_speeds_span_where_loudness_changes(velocities: list[float], expected: tuple[float, float]) -> None:
    speeds = np.geomspace(0.01, 0.5, 4).round(4)
    survey = pd.DataFrame({"down_velocity_mps": speeds, "on_velocity": velocities})
    assert useful_speeds(survey, 0.01, 0.5) == pytest.approx(expected, rel=1e-3)
