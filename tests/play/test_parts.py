"""Building blocks of `play` on synthetic inputs: dynamics map, scoring, stroke tables, scheduling."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pianobot.io.midifile import Note
from pianobot.play.dynamics import DynamicsMap
from pianobot.play.schedule import PLAN_COLUMNS, note_row, schedule
from pianobot.play.score import score_performance
from pianobot.play.settings import PlaySettings
from pianobot.play.strokes import StrokeGeometry, StrokeTable
from pianobot.spec import RigSpec


def test_dynamics_map_linear_and_absolute() -> None:
    mapped = DynamicsMap.fit([40, 75, 110], (2.0, 12.0), "mapped")
    assert mapped.apply([40, 75, 110]).tolist() == pytest.approx([2.0, 7.0, 12.0])
    assert "40–110 → 2.0–12.0" in mapped.describe()
    absolute = DynamicsMap.fit([1, 5, 100], (2.0, 12.0), "absolute")
    assert absolute.apply([1, 5, 100]).tolist() == [2.0, 5.0, 12.0]
    flat = DynamicsMap.fit([64, 64], (2.0, 12.0), "mapped")
    assert flat.apply([64]).tolist() == [7.0]


def test_score_counts_hits_and_errors() -> None:
    target = [Note(60, 0.0, 1.0, 40), Note(62, 2.0, 3.0, 80), Note(64, 4.0, 5.0, 100)]
    played = [Note(60, 0.01, 0.8, 5), Note(62, 2.2, 2.9, 9), Note(65, 4.0, 5.0, 9)]
    score = score_performance(target, played, [4.0, 8.0, 10.0])
    assert score.f1 == pytest.approx(1 / 3)  # only the first is within 50 ms with the right pitch
    assert score.notes_matched == 2  # the late one still counts for timing
    assert score.onset_mean_ms == pytest.approx((10 + 200) / 2)
    assert score.onset_rms_ms == pytest.approx(np.sqrt((0.01**2 + 0.2**2) / 2) * 1e3)
    assert score.velocity_mae == pytest.approx(1.0)
    assert score.velocity_mae_unmapped == pytest.approx((35 + 71) / 2)
    assert score.duration_mae_ms == pytest.approx((210 + 300) / 2)


class _Linear:
    """A fake predictor: loud with speed, silent below 0.02 m/s, lead = 0.02 m / speed."""

    def predict(self, frame: pd.DataFrame) -> pd.DataFrame:
        v = frame["down_velocity_mps"].to_numpy(float)
        hold = frame["hold_s"].to_numpy(float)
        silent = v < 0.02
        return pd.DataFrame({
            "on_velocity": np.where(silent, np.nan, 200 * v),
            "p_silent": silent.astype(float),
            "lead_s": np.where(silent, np.nan, 0.02 / v),
            "midi_hold_s": np.where(silent, np.nan, 0.1 + hold),
        }, index=frame.index)


GEOMETRY = StrokeGeometry(distance_m=0.002, depth_m=0.025, acceleration_mps2=2.0, up_velocity_mps=0.7)


def test_stroke_table_inverts_the_model() -> None:
    table = StrokeTable.build(_Linear(), -60.0, GEOMETRY, PlaySettings(), 0.06)  # type: ignore[arg-type]
    lo, hi = table.velocity_range
    assert lo >= 4.0 - 1e-9 and hi == pytest.approx(12.0)
    assert float(table.inverse(8.0)) == pytest.approx(0.04, rel=1e-3)
    assert float(table.lead(0.04)) == pytest.approx(0.5, rel=0.05)
    assert float(table.arm_hold_for(0.04, 0.6)) == pytest.approx(0.5)
    assert table.release_s(0.04, 0.5) == pytest.approx(0.5 + 0.6, rel=0.05)
    assert table.fastest_lead_for(0.5, 0.02) == pytest.approx(0.04, rel=0.05)


def _schedule(notes: list[Note], targets: list[float]) -> pd.DataFrame:
    settings = PlaySettings()
    table = StrokeTable.build(_Linear(), -60.0, GEOMETRY, settings, 0.06)  # type: ignore[arg-type]
    speeds = table.inverse(targets)
    rows = [note_row(i, n, t, table, float(v), 2.0, "") for i, (n, t, v) in enumerate(zip(notes, targets, speeds, strict=True))]
    return schedule(pd.DataFrame(rows, columns=list(PLAN_COLUMNS)), {-60.0: table}, settings, RigSpec())


def test_a_restrike_waits_for_the_predicted_note_off_and_a_tight_note_is_played_louder() -> None:
    # Same key twice, 1.5 s apart: the first note's hold is cut so its note-off comes in time.
    frame = _schedule([Note(60, 0.0, 1.4, 64), Note(60, 1.5, 2.5, 64)], [6.0, 6.0])
    first, second = frame.iloc[0], frame.iloc[1]
    assert (frame["status"] == "play").all()
    assert first.hold_s < 1.3 - 0.1  # shortened from the written 1.4 s
    assert second.start_s >= first.start_s + first.predicted_release_s + PlaySettings().restrike_margin_s - 1e-9
    # 0.9 s apart the quiet second note (lead 0.02/0.025 = 0.8 s) does not fit; a faster one does.
    frame = _schedule([Note(60, 0.0, 0.1, 64), Note(60, 0.9, 1.0, 64)], [12.0, 5.0])
    assert frame.iloc[1].status == "play"
    assert frame.iloc[1].predicted_velocity > 5.0 + 1.0
    assert "louder than asked" in frame.iloc[1].reason


def test_a_note_that_cannot_fit_is_skipped_and_the_previous_hold_is_kept() -> None:
    frame = _schedule([Note(60, 0.0, 1.0, 64), Note(60, 0.3, 0.4, 64), Note(60, 3.0, 3.5, 64)], [10.0, 10.0, 10.0])
    assert list(frame["status"]) == ["play", "skip", "play"]
    assert "no time to release and re-strike" in frame.iloc[1].reason
    # The skipped note did not cost the first one its length.
    assert frame.iloc[0].predicted_midi_hold_s == pytest.approx(1.0, abs=0.05)
