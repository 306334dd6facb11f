"""Regenerate the README tour's two images from a fresh simulated sweep.

    .venv/bin/python docs/make_tour_images.py

- docs/tour-report-stages.png: the run report's "Keystroke stages" section as a browser shows
  it (headless Chromium screenshot of that section alone);
- docs/tour-fit-maps.png: the figure `pianobot fit --plot` writes.

Both are reduced to a 256-colour palette to keep the repository small.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from PIL import Image, ImageChops

from pianobot.analysis.learn.run import fit_runs, load_trials
from pianobot.reports.command_figures import learned_maps, save_png
from pianobot.reports.run_report import build_run_report
from pianobot.run import run_sweep

DOCS = Path(__file__).resolve().parent
SPEC = DOCS.parent / "experiments" / "soft_lhs.yaml"
SECTION = "keystroke-stages-measured-and-model"
WIDTH_PX = 1000


def _small_png(source: Path, target: Path) -> None:
    image = Image.open(source).convert("RGB")
    background = Image.new("RGB", image.size, (255, 255, 255))
    box = ImageChops.difference(image, background).getbbox()  # trim the white margin
    if box is not None:
        image = image.crop((0, 0, image.size[0], min(image.size[1], box[3] + 20)))
    image.quantize(colors=256, method=Image.Quantize.MEDIANCUT).save(target, optimize=True)
    print(f"{target.name}: {image.size[0]}×{image.size[1]} px, {target.stat().st_size // 1024} KB")


def _section_page(report: Path, section: str) -> str:
    text = report.read_text(encoding="utf-8")
    style = re.search(r"<style>.*?</style>", text, flags=re.S)
    found = re.search(rf'<section id="{section}">.*?</section>', text, flags=re.S)
    if style is None or found is None:
        raise SystemExit(f"section {section} not found in {report}")
    return f'<!DOCTYPE html><html><head><meta charset="utf-8">{style.group(0)}</head><body>{found.group(0)}</body></html>'


def main() -> None:
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        sys.exit("needs chromium (apt-get install chromium)")
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        data = tmp / "data"
        run_id = run_sweep(SPEC, data_dir=data, progress=False).run_id
        report = build_run_report([run_id], data, tmp / "report.html")
        page = tmp / "section.html"
        page.write_text(_section_page(report, SECTION), encoding="utf-8")
        shot = tmp / "section.png"
        subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                        "--no-first-run", "--disable-background-networking", "--disable-component-update",
                        "--disable-sync", f"--user-data-dir={tmp / 'profile'}", "--hide-scrollbars",
                        f"--window-size={WIDTH_PX},2600", f"--screenshot={shot}", page.as_uri()],
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120)
        _small_png(shot, DOCS / "tour-report-stages.png")
        result = fit_runs([run_id], data, kinds=["gp", "poly"], out_dir=tmp / "models")
        from pianobot.analysis.learn.predictors import load_predictor

        predictors = {kind: load_predictor(path) for kind, path in result.saved.items()}
        figure = save_png(learned_maps(load_trials([run_id], data), predictors), tmp / "fit.png", dpi=90)
        _small_png(figure, DOCS / "tour-fit-maps.png")


if __name__ == "__main__":
    main()
