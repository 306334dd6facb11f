"""The run report is one self-contained HTML file: figures embedded, no external links."""

from __future__ import annotations

import re
import sys
from html.parser import HTMLParser
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "analysis"))
import pandas as pd  # noqa: E402
from _synthetic_runs import linear_keystrokes, sounded_trials, write_run  # noqa: E402

from pianobot.physics.msd import MSDParams  # noqa: E402
from pianobot.reports.html import Section, table_html, write_page  # noqa: E402
from pianobot.reports.run_report import build_run_report  # noqa: E402


class _Collector(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.imgs: list[str] = []
        self.links: list[str] = []
        self.tables = 0

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if tag == "img":
            self.imgs.append(a.get("src") or "")
        if tag == "table":
            self.tables += 1
        for key in ("href", "src"):
            value = a.get(key) or ""
            if value and tag != "img" and not value.startswith("#"):  # in-page anchors are fine
                self.links.append(value)
        if tag in ("script", "link"):
            self.links.append(tag)


def _parse(path: Path) -> _Collector:
    c = _Collector()
    c.feed(path.read_text())
    return c


def test_report_with_trajectories(data_dir: Path, tmp_path: Path) -> None:
    trials, samples = linear_keystrokes(MSDParams(), seed=0, speeds_mps=(0.02, 0.05))
    run = write_run(data_dir, trials, samples)
    page = _parse(build_run_report([run], data_dir, tmp_path / "r.html"))
    assert len(page.imgs) >= 5 and all(src.startswith("data:image/png;base64,") for src in page.imgs)
    assert page.links == [] and page.tables >= 3


def test_report_without_trajectories_still_complete(data_dir: Path, tmp_path: Path) -> None:
    run = write_run(data_dir, sounded_trials(0), None)
    path = build_run_report([run], data_dir, tmp_path / "r.html", cv_table=pd.DataFrame({"model": ["poly"], "r2": [0.9]}))
    text = path.read_text()
    assert "No trajectories" in text and "grouped cross-validation" in text
    assert not re.search(r"https?://", text)


def test_html_helpers_escape_and_format(tmp_path: Path) -> None:
    frame = pd.DataFrame({"name": ["<b>"], "value": [float("nan")]})
    html = table_html(frame)
    assert "&lt;b&gt;" in html and "–" in html
    out = write_page(tmp_path / "p.html", "T", [Section("S").add(html)])
    assert out.read_text().startswith("<!DOCTYPE html>")


def _assert_self_contained(path: Path, *, min_figures: int, min_tables: int) -> str:
    page = _parse(path)
    assert len(page.imgs) >= min_figures
    assert all(src.startswith("data:image/png;base64,") and len(src) > 200 for src in page.imgs)
    assert page.links == [], page.links  # no href/src to anything, no <script>, no <link>
    assert page.tables >= min_tables
    text = path.read_text()
    assert not re.search(r"https?://", text)
    return text


def test_report_on_quickstart_sim_run(data_dir: Path, tmp_path: Path) -> None:
    from pianobot.physics.model import KeystrokeModel, save_model
    from pianobot.run import run_sweep

    spec = Path(__file__).resolve().parents[2] / "experiments" / "quickstart.yaml"
    outcome = run_sweep(spec, data_dir=data_dir, progress=False)
    model = save_model(KeystrokeModel.study(), tmp_path / "model.json")
    text = _assert_self_contained(build_run_report([outcome.run_id], data_dir, tmp_path / "r.html", model_file=model),
                                  min_figures=6, min_tables=4)
    for heading in ("Provenance", "Parameter coverage", "Sound", "Keystroke stages", "Model"):
        assert heading in text


def test_report_on_fixture_imports(zhang2022: Path, data_dir: Path, tmp_path: Path) -> None:
    from pianobot.io.importers import import_keystroke_log, import_mocap

    log = import_keystroke_log(zhang2022 / "data/soft/ctrl_midi/soft_60_angle_45.txt", data_dir).run_id
    take = import_mocap(zhang2022 / "zzz/zzz40.csv", data_dir, vacuum_kpa=-40.0).run_id
    text = _assert_self_contained(build_run_report([log, take], data_dir, tmp_path / "r.html"),
                                  min_figures=5, min_tables=4)
    assert log in text and take in text


def test_the_parameter_table_reads_the_model_as_identify_wrote_it() -> None:
    from pianobot.reports.run_tables import parameter_table

    # A per-level k1 (stored as the magnitude 40) and a coupling given as shares of the finger's.
    params = MSDParams(k1_table=((40.0, 127.4), (80.0, 190.0)), k0_over_k1=0.7449, c0_over_c1=0.8)
    intervals = {"k1_npm@-40kPa": {"ci95": [110.0, 140.0]}, "c0_nspm": {"ci95": [0.07, 2.4]}}
    table = parameter_table(params, intervals).set_index("parameter")
    k1 = table.loc["finger stiffness k1 at -40 kPa"]  # it read "at 40 kPa", without its interval
    assert (k1["value"], k1["95 % low"], k1["95 % high"]) == (127.4, 110.0, 140.0)
    assert not any("blank: = k1" in p or "blank: = c1" in p for p in table.index)  # k0 is 0.74 k1, not k1
    assert table.loc["arm–fingertip stiffness as a share of the finger's, k0/k1", "value"] == 0.7449
    tied = parameter_table(MSDParams(), None).set_index("parameter")
    assert tied.loc["arm–fingertip stiffness as a share of the finger's, k0/k1", "value"] == 1.0  # k0 = k1
