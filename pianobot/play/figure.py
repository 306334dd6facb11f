"""Figures of a play run: the piano roll (target vs played, per-note status) and the warm-up fit."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pianobot.io.midifile import Note

# Outline colour of a target note by its score status (see `pianobot.play.score`).
STATUS_COLORS = {"matched": "tab:green", "late": "tab:red", "early": "tab:purple", "missed": "black",
                 "skipped": "tab:gray"}


def piano_roll(target: Sequence[Note], played: Sequence[Note], path: Path, *, title: str = "",
               status: Sequence[str] | None = None) -> Path:
    """Write the piano roll (`piano_roll_figure`) as a PNG."""
    return _save(piano_roll_figure(target, played, title=title, status=status), path)


def warmup_figure(trials: pd.DataFrame, predictor: Any, path: Path, *, title: str = "") -> Path:
    """Write the warm-up figure (`warmup_fit_figure`) as a PNG."""
    return _save(warmup_fit_figure(trials, predictor, title=title), path)


def _save(fig: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def piano_roll_figure(target: Sequence[Note], played: Sequence[Note], *, title: str = "",
                      status: Sequence[str] | None = None) -> Any:
    """Pitch over time: target notes outlined in the colour of their status (matched, late,
    early, missed; skipped dashed), played notes filled (darker = louder). A matplotlib Figure."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    fig, ax = plt.subplots(figsize=(10, 4), dpi=110)
    loudest = max([n.velocity for n in played] + [1])
    marks = list(status) if status is not None else ["matched"] * len(target)
    for n, mark in zip(target, marks, strict=True):
        ax.add_patch(Rectangle((n.onset_s, n.pitch - 0.4), n.duration_s, 0.8, fill=False,
                               edgecolor=STATUS_COLORS.get(mark, "tab:blue") if status is not None else "tab:blue",
                               linewidth=1.4, linestyle="--" if mark == "skipped" else "-"))
    for n in played:
        shade = 0.25 + 0.75 * n.velocity / loudest
        ax.add_patch(Rectangle((n.onset_s, n.pitch - 0.3), max(n.duration_s, 0.01), 0.6,
                               color="tab:orange", alpha=shade, linewidth=0))
    everything = list(target) + list(played)
    if everything:
        ax.set_xlim(min(n.onset_s for n in everything) - 0.2, max(n.offset_s for n in everything) + 0.2)
        ax.set_ylim(min(n.pitch for n in everything) - 1.5, max(n.pitch for n in everything) + 1.5)
    ax.set_xlabel("time (s, song clock at the tempo played)")
    ax.set_ylabel("MIDI note")
    ax.set_title(title or "target (outline) vs played (filled, darker = louder)")
    if status is None:
        ax.plot([], [], color="tab:blue", label="target")
    else:
        for mark, colour in STATUS_COLORS.items():
            count = marks.count(mark)
            if count:
                ax.plot([], [], color=colour, linestyle="--" if mark == "skipped" else "-",
                        label=f"{mark} ({count})")
    ax.plot([], [], color="tab:orange", linewidth=6, label="played")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    return fig


def warmup_fit_figure(trials: pd.DataFrame, predictor: Any, *, title: str = "") -> Any:
    """The warm-up: loudness and lead over down velocity, its strokes and the fitted maps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (loud, lead) = plt.subplots(1, 2, figsize=(10, 3.6), dpi=110)
    for level, group in trials.groupby("vacuum_kpa"):
        sounded = group[group["status"] == "ok"]
        silent = group[group["status"] == "silent"]
        grid = np.linspace(float(group["down_velocity_mps"].min()), float(group["down_velocity_mps"].max()), 100)
        first = group.iloc[0]
        frame = pd.DataFrame({"down_velocity_mps": grid, "hold_s": 0.0, "vacuum_kpa": float(str(level)),
                              **{c: float(first[c]) for c in ("distance_m", "depth_m", "acceleration_mps2",
                                                              "up_velocity_mps")}})
        fit = predictor.predict(frame)
        label = f"{float(str(level)):g} kPa"
        (line,) = loud.plot(grid * 1e3, fit["on_velocity"].where(fit["p_silent"] < 0.5), label=f"fit {label}")
        loud.scatter(sounded["down_velocity_mps"] * 1e3, sounded["on_velocity"], color=line.get_color(), s=14)
        loud.scatter(silent["down_velocity_mps"] * 1e3, np.zeros(len(silent)), color=line.get_color(), marker="x",
                     s=18)
        lead.plot(grid * 1e3, fit["lead_s"] * 1e3, color=line.get_color(), label=f"fit {label}")
        lead.scatter(sounded["down_velocity_mps"] * 1e3, sounded["t_on_s"] * 1e3, color=line.get_color(), s=14)
    loud.set_xlabel("down velocity (mm/s)")
    loud.set_ylabel("MIDI on-velocity (x: silent)")
    lead.set_xlabel("down velocity (mm/s)")
    lead.set_ylabel("motion start → note-on (ms)")
    loud.legend(fontsize=8)
    fig.suptitle(title or "warm-up: keystrokes (dots) and the fitted maps (lines)")
    fig.tight_layout()
    return fig
