"""The piano-roll figure: target notes as outlines, played notes filled by loudness."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from pianobot.io.midifile import Note


def piano_roll(target: Sequence[Note], played: Sequence[Note], path: Path, *, title: str = "") -> Path:
    """Write a PNG: pitch over time, target (outline) vs played (filled, darker = louder)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    fig, ax = plt.subplots(figsize=(10, 4), dpi=110)
    loudest = max([n.velocity for n in played] + [1])
    for n in target:
        ax.add_patch(Rectangle((n.onset_s, n.pitch - 0.4), n.duration_s, 0.8, fill=False,
                               edgecolor="tab:blue", linewidth=1.2))
    for n in played:
        shade = 0.25 + 0.75 * n.velocity / loudest
        ax.add_patch(Rectangle((n.onset_s, n.pitch - 0.3), max(n.duration_s, 0.01), 0.6,
                               color="tab:orange", alpha=shade, linewidth=0))
    everything = list(target) + list(played)
    if everything:
        ax.set_xlim(min(n.onset_s for n in everything) - 0.2, max(n.offset_s for n in everything) + 0.2)
        ax.set_ylim(min(n.pitch for n in everything) - 1.5, max(n.pitch for n in everything) + 1.5)
    ax.set_xlabel("time (s, song clock)")
    ax.set_ylabel("MIDI note")
    ax.set_title(title or "target (outline) vs played (filled, darker = louder)")
    ax.plot([], [], color="tab:blue", label="target")
    ax.plot([], [], color="tab:orange", linewidth=6, label="played")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path
