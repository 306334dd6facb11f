"""The report's figures: the keystroke-stages figure and the silent-keystroke map."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "analysis"))
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pytest  # noqa: E402
from _synthetic_runs import linear_sweep  # noqa: E402

from pianobot.analysis.greybox.load import load_batch  # noqa: E402
from pianobot.analysis.greybox.stages import STAGE_NAMES  # noqa: E402
from pianobot.analysis.identify.fit import simulate_batch  # noqa: E402
from pianobot.physics.msd import MSDParams  # noqa: E402
from pianobot.reports import figures  # noqa: E402


def test_stages_figure_shows_one_keystroke_with_the_physical_model(data_dir: Path) -> None:
    run = linear_sweep(data_dir, seed=5, levels_kpa=(-60.0,), speeds_mps=(0.02, 0.06), depths_m=(0.03,), repeats=1)
    batch, _ = load_batch([run], data_dir)
    x1m, x2m = simulate_batch(batch, MSDParams())
    fast = int(np.argmin(np.isfinite(batch.x2_m).sum(axis=1)))  # the shortest keystroke of the run
    t = batch.row_times_s(fast)
    fig = figures.stages(t, batch.x0_m[fast], batch.x1_m[fast], batch.x2_m[fast], x1m[fast], x2m[fast],
                         distance_m=float(batch.distance_m[fast]))
    top, bottom = fig.axes[:2]
    lo, hi = top.get_xlim()
    last = t[np.flatnonzero(np.isfinite(batch.x2_m[fast]))[-1]]
    assert lo <= 0.05 and hi <= last + 0.1 * last  # its own keystroke, not the slow one's rest
    assert hi < 0.6 * t[-1]
    # Stage names live in a legend (no free text on the axes that could collide).
    assert not top.texts and not bottom.texts
    labels = [text.get_text() for legend in fig.legends for text in legend.get_texts()]
    assert [label.split()[1] for label in labels] == list(STAGE_NAMES)
    # The model key stays at rest until the fingertip, starting 50 mm above, reaches it.
    model = next(line for line in bottom.get_lines() if line.get_label() == "key model")
    tm, x2_model = (np.asarray(a, dtype=float) for a in model.get_data())
    fingertip = next(line for line in top.get_lines() if line.get_label() == "fingertip model")
    above = np.asarray(fingertip.get_ydata(), dtype=float) < -0.1  # mm below the key's rest surface
    touch = int(np.argmin(above))  # the first sample within 0.1 mm of the key
    assert touch > 10 and np.all(x2_model[:touch] == 0.0)
    assert np.nanmax(x2_model) > 1.0 and tm[0] >= lo


def _trials(depth_m: float, speed: float, vacuum: float, silent: list[bool]) -> list[dict[str, object]]:
    return [{"status": "silent" if s else "ok", "on_velocity": np.nan if s else 20.0, "depth_m": depth_m,
             "down_velocity_mps": speed, "vacuum_kpa": vacuum} for s in silent]


def test_silent_map_counts_repeats_per_setting_and_depth() -> None:
    rows = (_trials(0.025, 0.02, -40, [True, False, True]) + _trials(0.025, 0.04, -40, [False, False])
            + _trials(0.03, 0.02, -40, [False, False]) + _trials(0.03, 0.02, -80, [True]))
    trials = pd.DataFrame(rows)
    table = figures.silent_fraction(trials).set_index(["depth_m", "down_velocity_mps", "vacuum_kpa"])
    assert table.loc[(0.025, 0.02, -40), "keystrokes"] == 3 and table.loc[(0.025, 0.02, -40), "silent"] == 2
    assert table.loc[(0.03, 0.02, -80), "silent_fraction"] == 1.0
    fig = figures.silent_map(trials)
    panels = [ax for ax in fig.axes if ax.get_title()]
    assert [ax.get_title() for ax in panels] == ["depth 25 mm", "depth 30 mm"]
    # Overlapping repeats are counted, not drawn on top of each other.
    assert sorted(t.get_text() for t in panels[0].texts) == ["0/2", "2/3"]
    assert len(panels[0].collections[0].get_offsets()) == 2


def test_silent_map_without_midi_says_so() -> None:
    trials = pd.DataFrame({"status": ["ok"] * 3, "on_velocity": [np.nan] * 3, "down_velocity_mps": [0.01] * 3,
                           "vacuum_kpa": [-40.0] * 3})
    fig = figures.silent_map(trials)
    assert figures.silent_fraction(trials).empty
    assert any("no MIDI" in t.get_text() for ax in fig.axes for t in ax.texts)


@pytest.mark.parametrize("n_depths", [1, 12])
def test_silent_map_of_a_continuous_sweep_is_one_unlabelled_panel(n_depths: int) -> None:
    rng = np.random.default_rng(0)
    n = 80
    trials = pd.DataFrame({"status": np.where(rng.random(n) < 0.3, "silent", "ok"),
                           "depth_m": rng.choice(np.linspace(0.02, 0.035, n_depths), n),
                           "down_velocity_mps": rng.uniform(0.01, 0.06, n), "vacuum_kpa": rng.uniform(-80, 0, n)})
    trials["on_velocity"] = np.where(trials["status"] == "silent", np.nan, 30.0)
    fig = figures.silent_map(trials)
    panels = [ax for ax in fig.axes if ax.get_title()]
    assert len(panels) == 1 and not panels[0].texts
    assert len(panels[0].collections[0].get_offsets()) == n


def test_bode_draws_the_fingertip_only_when_asked() -> None:
    """The report's Bode figure is also `model bode --plot`'s, which adds the fingertip's |X1/X0|."""
    plain = figures.bode(MSDParams(), [-20.0, -60.0])
    both = figures.bode(MSDParams(), [-60.0], fingertip=True, title="at -60 kPa")
    labels = [line.get_label() for line in plain.axes[0].get_lines()]
    assert sum("fingertip" in lab for lab in labels) == 0 and sum("kPa: " in lab for lab in labels) == 2
    lines = [line for line in both.axes[0].get_lines() if "fingertip" in str(line.get_label())]
    assert len(lines) == 1 and np.max(lines[0].get_ydata()) > 1.0  # the fingertip resonates too
    assert both.axes[0].get_title() == "at -60 kPa"
