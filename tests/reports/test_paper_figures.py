"""The run report reads like a paper: titled, provenance, units on every axis, residuals by stage."""

from __future__ import annotations

import re
import warnings
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

from pianobot.physics.model import KeystrokeModel, save_model
from pianobot.physics.msd import MSDParams
from pianobot.reports import figures
from pianobot.reports.run_report import build_run_report
from pianobot.reports.run_tables import coverage_table
from pianobot.reports.stage_residuals import stage_edges, stage_residuals
from pianobot.reports.style import quantity, unlabelled_axes
from pianobot.run import run_sweep

ROOT = Path(__file__).resolve().parents[2]


class _Page(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.h1 = ""
        self.lead = ""
        self.figures = 0
        self.shows = 0
        self._in: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        self._in.append("lead" if a.get("class") == "lead" else tag)
        self.figures += tag == "figure"
        self.shows += a.get("class") == "shows"

    def handle_endtag(self, tag: str) -> None:
        if self._in:
            self._in.pop()

    def handle_data(self, data: str) -> None:
        if self._in and self._in[-1] == "h1":
            self.h1 += data
        if self._in and self._in[-1] == "lead":
            self.lead += data


@pytest.fixture(scope="module")
def sweep_report(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, str]:
    data = tmp_path_factory.mktemp("data")
    outcome = run_sweep(ROOT / "experiments" / "quickstart.yaml", data_dir=data, progress=False)
    model = save_model(KeystrokeModel.study(), data / "model.json")
    cv = pd.DataFrame({"model": ["mean", "poly"], "rmse": [3.0, 1.0], "r2": [0.0, 0.9],
                       "hold_rmse_s": [0.3, 0.05], "silent_accuracy": [0.5, 0.9]})
    path = build_run_report([outcome.run_id], data, data / "r.html", model_file=model, cv_table=cv)
    return path.read_text(), outcome.run_id


def test_title_provenance_and_captions(sweep_report: tuple[str, str]) -> None:
    text, run_id = sweep_report
    page = _Page()
    page.feed(text)
    assert re.fullmatch(r"quickstart — \d{1,2} \w{3} \d{4}", page.h1.strip()), page.h1
    assert "[" not in page.lead and "16 keystrokes" in page.lead
    for needle in (run_id, "simulated rig", "quickstart.yaml (sha256 ", "lab time", "pianobot 0."):
        assert needle in text, needle
    assert re.search(r"lab time</td><td[^>]*>\d+ min", text), "lab time of the run"
    assert page.figures >= 6 and page.shows == page.figures  # every figure says what it shows
    assert "Model comparison" in text and "mean (baseline)" in text


def test_one_length_unit_in_text_and_tables(sweep_report: tuple[str, str]) -> None:
    text, _ = sweep_report
    visible = re.sub(r"<[^>]+>", " ", re.sub(r'src="data:[^"]+"', "", text))
    assert not re.search(r"\((m|m/s|m/s²|m/s\^2)\)", visible), "a length in metres"
    assert not re.search(r"\b\w+_(m|mps|mps2)\b", visible), "a raw column name with SI units"
    assert "(mm)" in visible and " mm/s " in visible


def test_coverage_table_is_compact_and_in_display_units() -> None:
    trials = pd.DataFrame({"vacuum_kpa": [0.0, -40.0, -80.0, -40.0], "depth_m": [0.02, 0.03, 0.03, 0.02],
                           "distance_m": [0.05] * 4, "down_velocity_mps": [0.01, 0.02, 0.03, 0.04]})
    table = coverage_table(trials).set_index("parameter")
    assert table.loc["pressing depth", "unit"] == "mm"
    assert table.loc["pressing depth", "min"] == pytest.approx(20.0)
    assert table.loc["vacuum", "levels"] == 3 and table.loc["vacuum", "varied"] == "varied"
    assert table.loc["finger–key distance", "varied"] == "fixed"
    assert table.loc["arm down velocity", "max"] == pytest.approx(40.0)


def _trials() -> pd.DataFrame:
    rng = np.random.default_rng(0)
    n = 60
    frame = pd.DataFrame({
        "vacuum_kpa": rng.choice([0.0, -40.0, -80.0], n), "down_velocity_mps": rng.uniform(0.01, 0.06, n),
        "depth_m": rng.choice([0.02, 0.03], n), "acceleration_mps2": rng.uniform(0.1, 1.0, n),
    })
    frame["on_velocity"] = np.where(frame["down_velocity_mps"] > 0.02, 300 * frame["down_velocity_mps"], np.nan)
    frame["status"] = np.where(frame["on_velocity"].isna(), "silent", "ok")
    return frame


def _all_figures() -> list[tuple[str, Figure]]:
    trials = _trials()
    t = np.linspace(0, 1, 121)
    x0 = np.clip(t - 0.1, 0, None) * 0.05
    x2 = np.clip(x0 - 0.02, 0, 0.01)
    found = stage_residuals([t], x0[None], x0[None], x2[None], x2[None] * 0.9, np.array([0.0]))
    return [
        ("velocity_vs_speed", figures.velocity_vs_speed(trials)),
        ("silent_map", figures.silent_map(trials)),
        ("coverage", figures.coverage(trials, ["vacuum_kpa", "down_velocity_mps", "depth_m", "acceleration_mps2"])),
        ("stages", figures.stages(t, x0, x0, x2, x0, x2, distance_m=0.0)),
        ("bode", figures.bode(MSDParams(), [0.0, -60.0])),
        ("residual_band", figures.residual_band(found)),
    ]


def test_every_axis_is_labelled_with_a_unit() -> None:
    for name, fig in _all_figures():
        assert unlabelled_axes(fig) == [], name
        for ax in fig.axes:
            for label in (ax.get_xlabel(), ax.get_ylabel()):
                if label:
                    assert re.search(r"\(.+\)|keystrokes", label), f"{name}: {label!r} has no unit"


def test_coverage_histograms_name_parameter_and_count() -> None:
    fig = figures.coverage(_trials(), ["vacuum_kpa", "depth_m"])
    assert [ax.get_xlabel() for ax in fig.axes] == ["vacuum (kPa)", "pressing depth (mm)"]
    assert all(ax.get_ylabel() == "keystrokes" for ax in fig.axes)
    depth_bars = [p.get_x() + p.get_width() / 2 for p in fig.axes[1].patches]
    assert sorted(round(x) for x in depth_bars) == [20, 30]  # one bar per level, in mm


def _synthetic_keystrokes(n: int, bottom_offset_m: float) -> tuple[list[np.ndarray], ...]:
    """Trapezoid keystrokes of different speeds; the 'model' misses only while the key is down."""
    rng = np.random.default_rng(1)
    times, x0s, x2s, models = [], [], [], []
    for _ in range(n):
        speed = rng.uniform(0.5, 2.0)
        t = np.arange(0.0, 3.0 / speed, 1 / 120)
        x0 = 0.03 * np.clip(np.minimum(speed * t, 3.0 - speed * t), 0, 1.0)
        x2 = np.clip(x0 - 0.01, 0, 0.01)  # the finger starts 10 mm above; 10 mm key dip
        model = x2.copy()
        model[x2 >= 0.9 * x2.max()] -= bottom_offset_m
        times.append(t)
        x0s.append(x0)
        x2s.append(x2)
        models.append(model)
    width = max(t.size for t in times)

    def pad(rows: list[np.ndarray]) -> np.ndarray:
        return np.array([np.r_[r, np.full(width - r.size, np.nan)] for r in rows])

    ts = [np.r_[t, t[-1] + (np.arange(width - t.size) + 1) / 120] for t in times]
    return ts, pad(x0s), pad(x2s), pad(models)


def test_stage_residuals_locate_a_miss_in_its_stage() -> None:
    ts, x0, x2, model = _synthetic_keystrokes(12, bottom_offset_m=0.5e-3)
    found = stage_residuals(ts, x0, x0, x2, model, np.full(len(ts), 0.01))
    table = found.table.set_index("stage")
    assert list(table.index) == ["1 approach", "2 contact", "3 press", "4 bottom", "5 release"]
    assert table.loc["4 bottom", "keystrokes"] == 12
    assert table.loc["4 bottom", "median_residual_m"] == pytest.approx(0.5e-3, rel=0.05)
    for stage in ("1 approach", "3 press"):
        assert abs(table.loc[stage, "median_residual_m"]) < 0.05e-3
    bottom = (found.phase >= 3.1) & (found.phase < 3.9)
    assert np.allclose(found.median_m[bottom], 0.5e-3, rtol=0.05)
    fig = figures.residual_band(found)
    assert len(fig.axes[0].get_lines()) <= 2  # a median and a zero line, not one line per keystroke


def test_quantities_scale_si_to_millimetres() -> None:
    assert quantity("depth_m").heading == "pressing depth (mm)" and quantity("depth_m").shown(0.02) == 20.0
    assert quantity("down_velocity_mps").heading == "arm down velocity (mm/s)"
    assert quantity("key_travel_m").unit == "mm" and quantity("peak_hz").heading == "peak (Hz)"


def test_every_figure_of_a_built_report_is_labelled(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The report as built (not only the figure functions alone): each embedded figure's axes."""
    from pianobot.reports import html, run_report

    seen: list[tuple[str, Figure]] = []
    embed = html.figure_html

    def capture(fig: Figure, caption: str = "", **kwargs: object) -> str:
        seen.append((caption, fig))
        return embed(fig, caption, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(run_report, "figure_html", capture)
    outcome = run_sweep(ROOT / "experiments" / "quickstart.yaml", data_dir=tmp_path, progress=False)
    model = save_model(KeystrokeModel.study(), tmp_path / "model.json")
    build_run_report([outcome.run_id], tmp_path, tmp_path / "r.html", model_file=model)
    assert len(seen) >= 6
    assert [(caption, unlabelled_axes(fig)) for caption, fig in seen
            if unlabelled_axes(fig)] == []


def test_stage_edges_take_traces_as_relative_to_rest_even_when_their_first_frames_dropped() -> None:
    # A sweep's traces start at motion start: with the first 0.1 s dropped, the first sample seen
    # is mid-approach, and a rest level taken from it would move every boundary late.
    t = np.arange(0.0, 2.0, 1 / 120)
    x0 = 0.03 * np.clip(np.minimum(t, 3.0 - t), 0, 1.0)  # 30 mm/s down, hold, up
    x2 = np.clip(x0 - 0.01, 0, 0.01)  # the finger starts 10 mm above the key
    x0[:12] = x2[:12] = np.nan
    edges = stage_edges(t, x0, x0, x2, 0.01)
    contact_s, key_move_s = 0.01 / 0.03, (0.01 + 2e-4) / 0.03
    assert edges[0] < 1 / 120  # motion starts where the trace does, not 0.1 s later
    assert edges[1] == pytest.approx(contact_s, abs=1 / 120)
    assert edges[2] == pytest.approx(key_move_s, abs=1 / 120)
    assert edges[1] < edges[2]  # the finger touches the key before the key moves


def test_a_rigid_fingers_velocities_are_one_series_in_the_legend() -> None:
    trials = _trials().assign(vacuum_kpa=np.nan)  # a rigid finger records no vacuum
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # matplotlib warns when a legend finds nothing to show
        fig = figures.velocity_vs_speed(trials)
    legend = fig.axes[0].get_legend()
    assert legend is not None and [t.get_text() for t in legend.get_texts()] == ["none (rigid)"]
    assert sum(len(line.get_xdata()) for line in fig.axes[0].get_lines()) == trials["on_velocity"].notna().sum()
