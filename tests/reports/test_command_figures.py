"""`--plot` on fit and import mocap: a PNG named on stdout, every axis labelled with its unit."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from cli_runner import invoke_cli
from PIL import Image

from pianobot.reports.command_figures import learned_maps, mocap_take
from pianobot.reports.style import unlabelled_axes
from pianobot.run import run_sweep

ROOT = Path(__file__).resolve().parents[2]


class _Linear:
    """A stand-in map: on-velocity grows with speed and vacuum (no pianobot model involved)."""

    def predict(self, frame: pd.DataFrame) -> pd.DataFrame:
        return pd.DataFrame({"on_velocity": 200 * frame["down_velocity_mps"] * (1 - frame["vacuum_kpa"] / 80)})


def test_learned_maps_one_panel_per_level_with_measured_points_and_curves() -> None:
    rng = np.random.default_rng(0)
    trials = pd.DataFrame({"vacuum_kpa": np.repeat([0.0, -40.0, -80.0], 20),
                           "down_velocity_mps": rng.uniform(0.01, 0.06, 60), "depth_m": 0.03})
    trials["on_velocity"] = np.where(trials["down_velocity_mps"] > 0.015, 40.0, np.nan)
    fig = learned_maps(trials, {"linear": _Linear()})
    shown = [ax for ax in fig.axes if ax.axison]
    assert [ax.get_title() for ax in shown] == ["-80 kPa (20 keystrokes)", "-40 kPa (20 keystrokes)",
                                                "0 kPa (20 keystrokes)"]
    assert unlabelled_axes(fig) == []
    assert shown[0].get_xlabel() == "arm down velocity (mm/s)"
    curve = next(line for line in shown[0].get_lines() if line.get_label() == "linear")
    x, y = (np.asarray(v, dtype=float) for v in curve.get_data())
    assert 10 <= x.min() and x.max() <= 60 and np.all(np.diff(y) > 0)  # mm/s, rising


def test_mocap_take_overlays_every_keystroke() -> None:
    t = np.arange(-0.2, 1.0, 1 / 120)
    samples, trials = [], []
    for i, speed in enumerate((0.01, 0.03, 0.05)):
        x0 = np.clip(speed * t, 0, 0.007)
        samples.append(pd.DataFrame({"trial_id": f"k{i}", "t_s": t, "x0_m": x0, "x1_m": 0.7 * x0,
                                     "x2_m": 0.5 * x0}))
        trials.append({"trial_id": f"k{i}", "t_start_s": 5.0 * i, "t_end_s": 5.0 * i + 1.0, "arm_speed_mps": speed})
    fig = mocap_take(pd.concat(samples), pd.DataFrame(trials))
    whole, overlaid = fig.axes[:2]
    assert len(overlaid.get_lines()) == 3 and len(whole.get_lines()) == 9
    assert unlabelled_axes(fig) == []
    assert overlaid.get_ylabel() == "key x2, down + (mm)"


def test_fit_plot_writes_a_png_and_says_where(data_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    run_id = run_sweep(ROOT / "experiments" / "quickstart.yaml", data_dir=data_dir, progress=False).run_id
    png = tmp_path / "fit.png"
    args = ["fit", run_id, "--data", str(data_dir), "--model", "poly", "--out-dir", str(tmp_path), "--plot", str(png)]
    code, out, err = invoke_cli(args, capsys, monkeypatch)
    assert code == 0, err
    assert f"figure written to {png}" in " ".join(out.split())
    assert Image.open(png).size[0] >= 600
    code, out, _ = invoke_cli([*args, "--json"], capsys, monkeypatch)
    assert json.loads(out)["plot"] == str(png)


def test_import_mocap_plot(zhang2022: Path, data_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                           monkeypatch: pytest.MonkeyPatch) -> None:
    png = tmp_path / "take.png"
    code, out, err = invoke_cli(["import", "mocap", str(zhang2022 / "zzz" / "zzz40.csv"), "--vacuum-kpa", "-40",
                                 "--data", str(data_dir), "--plot", str(png)], capsys, monkeypatch)
    assert code == 0, err
    assert f"figure written to {png}" in " ".join(out.split()) and Image.open(png).size[0] >= 600
    code, _, err = invoke_cli(["import", "mocap", str(zhang2022 / "zzz" / "zzz40.csv"), "--vacuum-kpa", "-40",
                               "--data", str(data_dir), "--plot", "/proc/no/such/dir/take.png"], capsys, monkeypatch)
    assert code == 2 and err.startswith("error: --plot:") and err.count("\n") == 1
    assert len(list((data_dir / "runs").iterdir())) == 1  # refused before a second import


def test_identified_model_figure_shows_the_law_and_a_hidden_resonance() -> None:
    from dataclasses import replace

    from pianobot.physics.msd import MSDParams
    from pianobot.reports.command_figures import identified_model

    damped = replace(MSDParams(), c2_nspm=34.0, k1_a_npm=219.0, k1_b_npm_per_kpa=-0.66)
    fig = identified_model(damped, {-40.0: (192.6, 170.2, 232.2), -80.0: (166.1, 145.5, 200.0)})
    stiff, gain = fig.axes[:2]
    assert unlabelled_axes(fig) == []
    labels = [t.get_text() for t in stiff.get_legend().get_texts()]
    assert labels[0].startswith("study: 75.41 + 1.19") and "-0.66" in labels[1]
    resonance = [t.get_text() for t in gain.get_legend().get_texts()]
    assert any("below the static gain" in text for text in resonance), resonance
