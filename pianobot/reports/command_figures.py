"""Figures written by `--plot` on `identify`, `fit`, `import mocap` and `model simulate`: one PNG
that checks the result by eye (`model bode --plot` draws the report's `figures.bode`).

Each figure is titled with what it shows and labelled with units (mm, mm/s), like the reports.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np
import pandas as pd
from matplotlib import colormaps
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.figure import Figure

from pianobot.errors import InputError
from pianobot.physics.linear import frequency_response
from pianobot.physics.msd import MSDParams
from pianobot.reports.style import (
    FULL_WIDTH_IN,
    label_axes,
    new_figure,
    quantity,
    resonance_label,
    style_axes,
)
from pianobot.spec.parameters import PREDICTOR_INPUTS

if TYPE_CHECKING:  # the simulator is not loaded for the other commands' figures
    from pianobot.physics.trajectory import Press
    from pianobot.physics.world import WorldKeystroke

#: More vacuum levels than this are too many panels: the most populated ones are shown.
MAX_LEVEL_PANELS = 6


class _Predicts(Protocol):
    def predict(self, frame: pd.DataFrame) -> pd.DataFrame: ...


def save_png(fig: Figure, path: Path, *, dpi: int = 120) -> Path:
    """Write `fig` as a PNG; an unwritable path is bad input (exit 2), not a traceback."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=dpi, facecolor="white")
    except OSError as exc:
        raise InputError(f"cannot write the figure ({exc.strerror})", str(path)) from None
    return path


def learned_maps(trials: pd.DataFrame, predictors: Mapping[str, _Predicts]) -> Figure:
    """On-velocity against arm down speed per vacuum level: measured keystrokes and each map.

    The maps are drawn with every other press parameter at its median over the level's
    keystrokes, so a curve is the map's answer for a typical press of that level.
    """
    frame = trials.dropna(subset=["down_velocity_mps"])
    counts = frame["vacuum_kpa"].fillna(0.0).value_counts()
    levels = sorted(counts.index[:MAX_LEVEL_PANELS].tolist())
    per_row = min(len(levels), 3) or 1
    n_rows = max(1, -(-len(levels) // per_row))
    fig = new_figure(FULL_WIDTH_IN, 2.9 * n_rows + 0.4)
    axes = fig.subplots(n_rows, per_row, squeeze=False, sharey=True).ravel()
    speed, loud = quantity("down_velocity_mps"), quantity("on_velocity")
    for ax, level in zip(axes, levels, strict=False):
        style_axes(ax)
        rows = frame[frame["vacuum_kpa"].fillna(0.0) == level]
        sounded = rows.dropna(subset=["on_velocity"])
        silent = rows[rows["on_velocity"].isna()]
        ax.plot(speed.shown(sounded["down_velocity_mps"]), sounded["on_velocity"], "o", ms=3, color="0.45",
                label="measured")
        if not silent.empty:
            ax.plot(speed.shown(silent["down_velocity_mps"]), np.zeros(len(silent)), "x", ms=4, color="C3",
                    label="silent (drawn at 0)")
        grid = np.linspace(rows["down_velocity_mps"].min(), rows["down_velocity_mps"].max(), 60)
        typical = rows.median(numeric_only=True)
        query = pd.DataFrame({c: np.full(grid.size, typical[c]) for c in typical.index
                              if c in PREDICTOR_INPUTS and c not in ("down_velocity_mps", "vacuum_kpa")
                              and np.isfinite(typical[c])})
        query["down_velocity_mps"] = grid
        query["vacuum_kpa"] = level
        for i, (kind, model) in enumerate(predictors.items()):
            predicted = model.predict(query)["on_velocity"].to_numpy(float)
            ax.plot(speed.shown(grid), predicted, color=f"C{i}", lw=1.6, label=kind)
        ax.set_title(f"{level:g} kPa ({len(rows)} keystrokes)", fontsize=9)
        label_axes(ax, speed, loud)
    for ax in axes[len(levels):]:
        ax.set_axis_off()
    # One legend naming every kind of mark, even those only some panels have (silent keystrokes).
    shown: dict[str, object] = {}
    for ax in axes[:len(levels)]:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            shown.setdefault(label, handle)
    axes[0].legend(list(shown.values()), list(shown), fontsize=7)
    fig.suptitle("Learned on-velocity maps against the measured keystrokes", fontsize=10)
    return fig


def mocap_take(samples: pd.DataFrame, trials: pd.DataFrame) -> Figure:
    """A Motive take as imported: the whole take with each keystroke shaded, then all of them
    overlaid from motion start, coloured by arm speed (a keystroke split at the wrong place stands out)."""
    fig = new_figure(FULL_WIDTH_IN, 6.0)
    whole, overlaid = fig.subplots(2, 1)
    style_axes(whole)
    style_axes(overlaid)
    mm = quantity("x2_m")
    order = trials.sort_values("t_start_s")
    speeds = order["arm_speed_mps"] if "arm_speed_mps" in order else order["down_velocity_mps"]
    finite = speeds.dropna()
    norm = Normalize(float(finite.min()) * 1e3, float(finite.max()) * 1e3) if not finite.empty else Normalize(0, 1)
    cmap = colormaps["viridis"]
    by_trial = {tid: group.sort_values("t_s") for tid, group in samples.groupby("trial_id")}
    for n, (_, trial) in enumerate(order.iterrows()):
        group = by_trial.get(trial["trial_id"])
        if group is None:
            continue
        t0 = float(trial["t_start_s"]) if np.isfinite(trial.get("t_start_s", np.nan)) else 0.0
        t = group["t_s"].to_numpy(float)
        for column, trace_colour, label in (("x0_m", "0.3", "arm x0"), ("x1_m", "C0", "fingertip x1"),
                                            ("x2_m", "C3", "key x2")):
            whole.plot(t0 + t, mm.shown(group[column].to_numpy(float)), color=trace_colour, lw=0.8,
                       label=label if n == 0 else None)
        end = float(trial.get("t_end_s", np.nan))
        if np.isfinite(end):
            whole.axvspan(t0, end, color="C2" if n % 2 else "C8", alpha=0.12, lw=0)
        whole.text(t0, 1.0, str(n + 1), transform=whole.get_xaxis_transform(), fontsize=6, va="bottom")
        speed = float(speeds.to_numpy(float)[n])
        colour = cmap(norm(speed * 1e3)) if np.isfinite(speed) else (0.5, 0.5, 0.5, 1.0)
        overlaid.plot(t, mm.shown(group["x2_m"].to_numpy(float)), color=colour, lw=0.9)
    low, high = whole.get_ylim()
    whole.set_ylim(low, high + 0.25 * (high - low))  # room for the legend above the traces
    whole.legend(fontsize=7, loc="upper right", ncol=3)
    label_axes(whole, "time in the take (s)", "displacement, down + (mm)")
    label_axes(overlaid, "time since motion start (s)", "key x2, down + (mm)")
    bar = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=overlaid)
    bar.set_label("arm speed (mm/s)", fontsize=9)
    bar.ax.tick_params(labelsize=8)
    fig.suptitle(f"Imported take: {len(order)} keystrokes (numbered, shaded) and their key traces",
                 fontsize=10)
    return fig


def plot_mocap_run(run_id: str, data_dir: Path, path: Path) -> Path:
    """`import mocap --plot`: the imported run's take figure, written to `path`."""
    from pianobot.store import load_run

    run = load_run(run_id, data_dir)
    samples = run.samples
    if "source" in samples:
        samples = samples[samples["source"] == "mocap"]
    return save_png(mocap_take(samples, run.trials), path)


class _Estimate(Protocol):
    @property
    def name(self) -> str: ...

    @property
    def value(self) -> float: ...

    @property
    def ci95(self) -> tuple[float, float]: ...


def k1_by_level(estimates: Iterable[_Estimate]) -> dict[float, tuple[float, float, float]]:
    """The per-level finger stiffness estimates (`k1_npm@-40kPa`) as {kPa: (k1, low, high)}."""
    found = {}
    for e in estimates:
        base, _, where = e.name.partition("@")
        if base == "k1_npm" and where.endswith("kPa"):
            found[float(where.removesuffix("kPa"))] = (e.value, *e.ci95)
    return found


def identified_model(params: MSDParams, k1_by_level: Mapping[float, tuple[float, float, float]],
                     *, title: str = "Identified model") -> Figure:
    """`identify --plot`: the finger's stiffness per vacuum level against the study's law, and
    the key's response to the arm at each level with its resonance peak.

    Args:
        params: the identified model.
        k1_by_level: per vacuum level (kPa), the identified k1 and its 95 % interval (N/m).
    """
    study = MSDParams()
    fig = new_figure(FULL_WIDTH_IN, 3.6)
    stiff, gain = fig.subplots(1, 2)
    style_axes(stiff)
    style_axes(gain)
    levels = sorted(k1_by_level) or [0.0]
    p = np.linspace(0.0, max(80.0, max(abs(v) for v in levels)), 50)
    stiff.plot(p, study.k1_a_npm + study.k1_b_npm_per_kpa * p, color="0.5", ls="--",
               label=f"study: {study.k1_a_npm:g} + {study.k1_b_npm_per_kpa:g}·|p|")
    stiff.plot(p, params.k1_a_npm + params.k1_b_npm_per_kpa * p, color="C0",
               label=f"identified: {params.k1_a_npm:.4g} + {params.k1_b_npm_per_kpa:.3g}·|p|")
    if k1_by_level:
        values = np.array([k1_by_level[v] for v in levels], dtype=float)
        stiff.errorbar(np.abs(levels), values[:, 0], yerr=[values[:, 0] - values[:, 1], values[:, 2] - values[:, 0]],
                       fmt="o", color="C0", capsize=3, label="per level (95 %)")
    stiff.legend(fontsize=7)
    label_axes(stiff, "vacuum |p| (kPa)", "finger stiffness k1 (N/m)")
    f = np.geomspace(0.5, 200.0, 400)
    for i, level in enumerate(levels):
        lp = params.at(level)
        g, _ = frequency_response(lp, f)
        label, peak_hz, peak_gain = resonance_label(lp, f"{level:g} kPa")
        gain.loglog(f, g, color=f"C{i % 10}", label=label)
        if math.isfinite(peak_hz):
            gain.plot([peak_hz], [peak_gain], "o", ms=4, color=f"C{i % 10}")
    gain.axvspan(7.0, 11.0, color="0.85", alpha=0.5, lw=0, label="real key rings (7–11 Hz)")
    gain.legend(fontsize=7)
    label_axes(gain, "frequency (Hz)", "key/arm amplitude |X2/X0| (mm/mm)")
    fig.suptitle(title, fontsize=10)
    return fig


def simulated_keystroke(k: WorldKeystroke, press: Press, vacuum_kpa: float) -> Figure:
    """`model simulate --plot`: arm, fingertip and key of one simulated keystroke, downwards
    positive, with its MIDI events marked."""
    fig = new_figure(FULL_WIDTH_IN, 4.5)
    ax = style_axes(fig.subplots())
    t = k.truth_t_s - k.t0_s
    ax.plot(t, k.truth_x0_m * 1e3, label="x0 arm")
    ax.plot(t, k.truth_x1_m * 1e3, label="x1 fingertip")
    ax.plot(t, (k.truth_x2_m + press.distance_m) * 1e3, label="x2 key (+ distance)")
    for e in k.midi:
        color = "tab:green" if e.type == "note_on" else "tab:red"
        ax.axvline(e.t_s - k.t0_s, color=color, ls="--", alpha=0.8)
        ax.text(e.t_s - k.t0_s, 0.97, f"{e.type} {e.velocity}", transform=ax.get_xaxis_transform(),
                color=color, rotation=90, va="top", ha="right", fontsize=8)
    ax.invert_yaxis()  # downward positive: draw "down" downwards
    ax.set(xlabel="time since motion start (s)", ylabel="displacement, down (mm)",
           title=f"Keystroke at {vacuum_kpa:g} kPa, {press.down_velocity_mps:g} m/s, depth {press.depth_m * 1e3:g} mm")
    ax.legend(loc="lower right")
    return fig
