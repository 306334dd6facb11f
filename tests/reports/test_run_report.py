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
            if a.get(key) and tag != "img":
                self.links.append(a[key] or "")
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
