"""The run report's figures (matplotlib, Agg): each function takes data and returns a Figure.

Every axis carries its quantity and unit (`reports.style`), lengths and speeds in mm.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from pianobot.analysis.greybox.stages import STAGE_NAMES
from pianobot.physics.linear import frequency_response
from pianobot.physics.msd import MSDParams
from pianobot.reports.stage_residuals import StageResiduals, stage_edges
from pianobot.reports.style import (
    FULL_WIDTH_IN,
    label_axes,
    new_figure,
    quantity,
    resonance_label,
    style_axes,
)

FloatArray = npt.NDArray[np.float64]

#: Around a keystroke's stages, how much rest to show before and after (fraction of its length).
STAGE_MARGIN = 0.05
#: Stage shading: light colours apart from the traces' (grey, blue, red).
STAGE_COLOURS = ("#fdf1c7", "#d9f0d3", "#e5d8f0", "#fcdcc5", "#d5ecf2")
#: Above this many settings per panel the silent map stops printing counts (they would collide).
MAX_LABELLED_SETTINGS = 40
#: Up to this many distinct values a parameter is a grid: its coverage plot has a bar per level.
MAX_LEVEL_BARS = 12


def velocity_vs_speed(trials: pd.DataFrame) -> Figure:
    """On-velocity against arm down speed, one series per vacuum level."""
    fig = new_figure(6, 4)
    ax = style_axes(fig.add_subplot())
    speed = quantity("down_velocity_mps")
    sounded = trials.dropna(subset=["on_velocity"])
    # A rigid finger's runs record no vacuum: one series of their own, not none.
    for vacuum, group in sounded.groupby("vacuum_kpa", dropna=False):
        label = "none (rigid)" if pd.isna(vacuum) else f"{float(str(vacuum)) + 0.0:g} kPa"
        ax.plot(speed.shown(group["down_velocity_mps"]), group["on_velocity"], "o", ms=3, label=label)
    label_axes(ax, speed, quantity("on_velocity"))
    if not sounded.empty:
        ax.legend(fontsize=7, title="vacuum", title_fontsize=7)
    else:
        ax.text(0.5, 0.5, "no sounded keystroke", transform=ax.transAxes, ha="center", va="center")
    return fig


def silent_fraction(trials: pd.DataFrame) -> pd.DataFrame:
    """Keystrokes and silent ones per setting (depth, vacuum, down speed).

    Repeats of a setting land on the same point of a scatter plot, where a silent and a sounded
    marker hide each other; counting per setting shows both. A keystroke is silent when its
    status says so and sounded when the piano reported a velocity; others (no MIDI recorded,
    e.g. an imported mocap take) are left out.
    """
    status = trials["status"] if "status" in trials else pd.Series("", index=trials.index)
    silent = status.eq("silent")
    sounded = trials["on_velocity"].notna() & ~silent
    known = trials.loc[silent | sounded].assign(silent=silent[silent | sounded].astype(int))
    keys = [c for c in ("depth_m", "vacuum_kpa", "down_velocity_mps") if c in known]
    known = known.dropna(subset=[c for c in keys if c != "depth_m"])
    if "depth_m" in known:
        known = known.assign(depth_m=known["depth_m"].fillna(-1.0))  # -1: depth not recorded
    if known.empty or len(keys) < 2:
        return pd.DataFrame(columns=[*keys, "keystrokes", "silent", "silent_fraction"])
    table = known.groupby(keys).agg(keystrokes=("silent", "size"), silent=("silent", "sum")).reset_index()
    return table.assign(silent_fraction=table["silent"] / table["keystrokes"])


def silent_map(trials: pd.DataFrame) -> Figure:
    """Silent fraction per setting over down speed and vacuum, one panel per pressing depth."""
    table = silent_fraction(trials)
    depths = sorted(table["depth_m"].unique()) if "depth_m" in table and not table.empty else [math.nan]
    if len(depths) > 6:  # a continuous depth sweep: one panel, depth not separated
        table, depths = table.assign(depth_m=math.nan), [math.nan]
    fig = new_figure(min(3.2 * len(depths), FULL_WIDTH_IN + 2.0) + 1.0, 3.6)
    axes = fig.subplots(1, len(depths), sharex=True, sharey=True, squeeze=False)[0]
    speed = quantity("down_velocity_mps")
    scatter = None
    for ax, depth in zip(axes, depths, strict=True):
        rows = table if math.isnan(depth) else table[table["depth_m"] == depth]
        most = max(float(table["keystrokes"].max()), 1.0) if not table.empty else 1.0
        size = (30.0 + 170.0 * rows["keystrokes"].to_numpy(float) / most) if not rows.empty else np.zeros(0)
        style_axes(ax)
        scatter = ax.scatter(speed.shown(rows["down_velocity_mps"]), rows["vacuum_kpa"], c=rows["silent_fraction"], s=size,
                             cmap="coolwarm", vmin=0.0, vmax=1.0, edgecolors="k", linewidths=0.5)
        if 0 < len(rows) <= MAX_LABELLED_SETTINGS:
            for v, p, k, n in rows[["down_velocity_mps", "vacuum_kpa", "silent", "keystrokes"]].to_numpy(float):
                ax.annotate(f"{k:.0f}/{n:.0f}", (speed.shown(v), p), xytext=(0, 9), textcoords="offset points",
                            ha="center", fontsize=7)
        title = "" if table.empty else "all depths" if math.isnan(depth) else (
            "depth not recorded" if depth < 0 else f"depth {1e3 * depth:g} mm")
        ax.set_title(title, fontsize=9)
        ax.set_xlabel(speed.heading)
        ax.margins(0.15)
    axes[0].set_ylabel(quantity("vacuum_kpa").heading)
    if table.empty:
        axes[0].set_axis_off()
        axes[0].text(0.5, 0.5, "no MIDI outcome recorded", transform=axes[0].transAxes, ha="center", va="center")
    elif scatter is not None:
        fig.colorbar(scatter, ax=list(axes), label="silent fraction (labels: silent/keystrokes)", fraction=0.05)
    return fig


def coverage(trials: pd.DataFrame, columns: list[str]) -> Figure:
    """Histogram of each varied parameter (what the run covered), three panels to a row."""
    per_row = min(max(len(columns), 1), 3)
    n_rows = max(1, math.ceil(len(columns) / per_row))
    fig = new_figure(FULL_WIDTH_IN, 2.3 * n_rows)
    for i, name in enumerate(columns):
        ax = style_axes(fig.add_subplot(n_rows, per_row, i + 1))
        q = quantity(name)
        values = q.shown(trials[name].dropna().astype(float))
        counts = values.round(9).value_counts().sort_index()
        if len(counts) <= MAX_LEVEL_BARS:  # a grid: one bar per level, not bins between levels
            gaps = np.diff(counts.index.to_numpy(float))
            width = 0.6 * float(gaps.min()) if gaps.size else 1.0
            ax.bar(counts.index.to_numpy(float), counts.to_numpy(), width=width, color="C0")
        else:
            ax.hist(values, bins=20, color="C0", edgecolor="white", lw=0.5)
        label_axes(ax, q, "keystrokes")
    return fig


def _window(t_s: FloatArray, edges: FloatArray, x0: FloatArray, x2: FloatArray) -> tuple[float, float]:
    """The keystroke's time span: its stages (or, without them, where the arm or key moves),
    with a little rest either side, within the samples."""
    finite = edges[np.isfinite(edges)]
    if finite.size >= 2:
        lo, hi = float(finite.min()), float(finite.max())
    else:
        moving = np.flatnonzero((np.abs(x0 - x0[0]) > 1e-4) | (np.abs(np.nan_to_num(x2)) > 1e-4))
        lo, hi = (float(t_s[moving[0]]), float(t_s[moving[-1]])) if moving.size else (float(t_s[0]), float(t_s[-1]))
    pad = STAGE_MARGIN * max(hi - lo, 1e-3)
    return max(lo - pad, float(t_s[0])), min(hi + pad, float(t_s[-1]))


def stages(t_s: FloatArray, x0: FloatArray, x1: FloatArray, x2: FloatArray,
           x1_model: FloatArray | None, x2_model: FloatArray | None, *, distance_m: float = 0.0) -> Figure:
    """One keystroke, measured (solid) and model (dashed), with the study's five stages shaded.

    Top: arm, fingertip and key surface in one frame — depth below the key's rest surface, so
    the fingertip starts `distance_m` above it and touches where its line meets the key's.
    Bottom: the key alone, at its own scale. Stage names are in the legend below the axes; the
    model traces end where the model does (lift-off: NaN from there, see `model_window`).
    """
    t = np.asarray(t_s, dtype=np.float64)
    edges = stage_edges(t, x0, x1, x2, distance_m)
    lo, hi = _window(t, edges, x0, x2)
    show = (t >= lo) & (t <= hi)
    fig = Figure(figsize=(FULL_WIDTH_IN, 6.2))
    top, bottom = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 2]})
    style_axes(top)
    style_axes(bottom)
    d_mm = 1e3 * distance_m
    top.plot(t[show], 1e3 * x0[show] - d_mm, color="0.3", lw=1.2, label="arm x0")
    top.plot(t[show], 1e3 * x1[show] - d_mm, color="C0", lw=1.2, label="fingertip x1")
    top.plot(t[show], 1e3 * x2[show], color="C3", lw=1.2, label="key x2")
    bottom.plot(t[show], 1e3 * x2[show], color="C3", lw=1.2, label="key x2 measured")
    if x1_model is not None and x2_model is not None:
        top.plot(t[show], 1e3 * x1_model[show] - d_mm, color="C0", ls="--", lw=1.2, label="fingertip model")
        top.plot(t[show], 1e3 * x2_model[show], color="C3", ls="--", lw=1.2, label="key model")
        bottom.plot(t[show], 1e3 * x2_model[show], color="k", ls="--", lw=1.0, label="key model")
        # The study's model describes the keystroke until the fingertip leaves the key.
        modelled = np.flatnonzero(np.isfinite(x2_model) & show)
        if modelled.size and modelled[-1] < np.flatnonzero(show)[-1]:
            for ax in (top, bottom):
                ax.axvline(t[modelled[-1]], color="k", ls=":", lw=1.0,
                           label="lift-off: model ends" if ax is bottom else None)
    handles = []
    for i, name in enumerate(STAGE_NAMES):
        a, b = edges[i], edges[i + 1]
        if np.isfinite(a) and np.isfinite(b) and b > a:
            for ax in (top, bottom):
                ax.axvspan(a, b, color=STAGE_COLOURS[i], alpha=0.5, lw=0)
            handles.append(Patch(color=STAGE_COLOURS[i], alpha=0.7, label=f"{i + 1} {name} ({b - a:.2f} s)"))
    top.set_ylabel("below key rest surface (mm)")
    bottom.set_ylabel("key x2 (mm, down +)")
    bottom.set_xlabel("time since motion start (s)")
    top.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    bottom.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    if handles:
        fig.legend(handles=handles, loc="lower center", bbox_to_anchor=(0.45, 0.0), ncol=min(len(handles), 5), fontsize=7,
                   title="stages", title_fontsize=7, frameon=False)
    top.set_xlim(lo, hi)
    fig.subplots_adjust(bottom=0.15, right=0.78, hspace=0.08)
    return fig


def bode(params: MSDParams, levels_kpa: list[float], *, fingertip: bool = False, title: str = "") -> Figure:
    """|X2/X0| and phase of the model at the given vacuum levels, each resonance peak marked
    (`fingertip`: the fingertip's |X1/X0| too, dashed). The report's figure and `model bode --plot`."""
    fig = new_figure(FULL_WIDTH_IN * 0.8, 5.0)
    mag, ph = fig.subplots(2, 1, sharex=True)
    style_axes(mag)
    style_axes(ph)
    f = np.geomspace(0.5, 200, 400)
    for i, p in enumerate(levels_kpa):
        lp = params.at(p)
        gain, phase = frequency_response(lp, f)
        label, peak_hz, peak_gain = resonance_label(lp, f"{p:g} kPa")
        mag.loglog(f, gain, color=f"C{i % 10}", label=label)
        if fingertip:
            gain1, _ = frequency_response(lp, f, output="x1")
            mag.loglog(f, gain1, color=f"C{i % 10}", ls="--", alpha=0.7, label=f"{p:g} kPa: fingertip |X1/X0|")
        if math.isfinite(peak_hz):
            mag.plot([peak_hz], [peak_gain], "o", ms=4, color=f"C{i % 10}")
        ph.semilogx(f, np.degrees(phase), color=f"C{i % 10}")
    mag.set_ylabel("key (fingertip)/arm amplitude (mm/mm)" if fingertip else "key/arm amplitude |X2/X0| (mm/mm)")
    label_axes(ph, "frequency (Hz)", "phase (°)")
    mag.legend(fontsize=7)
    if title:
        mag.set_title(title)
    return fig


def residual_band(found: StageResiduals) -> Figure:
    """Median key residual and the 10–90 % band over keystrokes, stage by stage."""
    fig = new_figure(FULL_WIDTH_IN, 3.4)
    ax = style_axes(fig.add_subplot())
    for i in range(len(STAGE_NAMES)):
        ax.axvspan(i, i + 1, color=STAGE_COLOURS[i], alpha=0.5, lw=0)
    ax.axhline(0.0, color="0.4", lw=0.8)
    if found.empty:
        ax.text(2.5, 0.0, "no keystroke with both a measured and a modelled key trace", ha="center")
    else:
        ax.fill_between(found.phase, 1e3 * found.low_m, 1e3 * found.high_m, color="C3", alpha=0.25, lw=0,
                        label="10–90 % of keystrokes")
        ax.plot(found.phase, 1e3 * found.median_m, color="C3", lw=1.6, label="median")
        ax.legend(fontsize=7, loc="best")
    ax.set_xlim(0, len(STAGE_NAMES))
    ax.set_xticks([i + 0.5 for i in range(len(STAGE_NAMES))],
                  [f"{i + 1} {name}" for i, name in enumerate(STAGE_NAMES)])
    ax.tick_params(axis="x", length=0)
    label_axes(ax, "keystroke stage (time scaled to each stage's length)",
               "key x2 residual, measured − model (mm)")
    return fig
