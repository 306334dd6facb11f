"""Every report type opens in a real browser (headless Chromium) without errors or broken images.

Skips when Chromium is absent; `.ci/run` installs the Debian package. The pages are opened from
disk as a reader would (file://), at a 1,024-pixel-wide window.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from cli_runner import invoke_cli
from headless import PageCheck, check_page, find_chromium

from pianobot.physics.model import KeystrokeModel, save_model
from pianobot.play import play_song
from pianobot.reports.run_report import build_run_report
from pianobot.run import run_sweep

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = find_chromium()
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (apt-get install chromium)")


def _check(path: Path) -> PageCheck:
    assert CHROMIUM is not None
    return check_page(path, CHROMIUM)


def _assert_clean(check: PageCheck, *, min_figures: int) -> None:
    assert check.errors == [], check.errors
    assert check.broken_images == [], check.broken_images
    assert len(check.images) >= min_figures and check.figures >= min_figures
    assert all(i["width"] >= 200 and i["height"] >= 100 for i in check.images), check.images
    # Nothing wider than the window: no sideways scrolling at 1,024 px.
    assert check.scroll_width <= check.inner_width, (check.scroll_width, check.inner_width)


def test_the_check_sees_console_errors_and_broken_images(tmp_path: Path) -> None:
    page = tmp_path / "bad.html"
    page.write_text('<!DOCTYPE html><html><body><img alt="not a png" src="data:image/png;base64,AAAA">'
                    '<img alt="missing" src="missing.png"><div style="width:3000px">wide</div>'
                    '<script>console.error("boom")</script></body></html>')
    check = _check(page)
    assert sorted(check.broken_images) == ["missing", "not a png"]
    assert any("boom" in e for e in check.errors) and any("missing.png" in e for e in check.errors)
    assert check.scroll_width > check.inner_width


def test_run_report_in_chromium(data_dir: Path, tmp_path: Path) -> None:
    outcome = run_sweep(ROOT / "experiments" / "quickstart.yaml", data_dir=data_dir, progress=False)
    model = save_model(KeystrokeModel.study(), tmp_path / "model.json")
    path = build_run_report([outcome.run_id], data_dir, tmp_path / "report.html", model_file=model)
    check = _check(path)
    _assert_clean(check, min_figures=6)
    assert check.title.startswith("quickstart — ")


def test_discovery_report_in_chromium(zhang2022: Path, data_dir: Path, tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    data = ["--data", str(data_dir)]
    code, _, err = invoke_cli(["import", "mocap", str(zhang2022 / "zzz" / "zzz40.csv"), "--vacuum-kpa", "-40",
                               "--json", *data], capsys, monkeypatch)
    assert code == 0, err
    run_id = next((data_dir / "runs").iterdir()).name
    out = tmp_path / "discover.html"
    code, _, err = invoke_cli(["discover", run_id, "--out", str(out), "--json", *data], capsys, monkeypatch)
    assert code == 0, err
    _assert_clean(_check(out), min_figures=2)


def test_play_report_in_chromium(data_dir: Path, tmp_path: Path) -> None:
    result = play_song(ROOT / "experiments" / "songs" / "mary.mid", data_dir=data_dir, model=None, planner="model",
                       adapt=False, dry_run=False, tempo_scale=1.0, transpose=0, track=None, dynamics="mapped",
                       rig="sim", seed=0, plot=None)
    pages = [Path(p) for p in result.files.values() if str(p).endswith(".html")]
    if not pages:
        pytest.skip("play writes no HTML report (only a piano-roll PNG)")
    for page in pages:
        _assert_clean(_check(page), min_figures=1)
