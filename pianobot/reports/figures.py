"""The run report's figures (matplotlib, Agg): each function takes data and returns a Figure."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from pianobot.analysis.greybox.phases import STAGE_NAMES, segment_keystroke
from pianobot.physics.msd import MSDParams, frequency_response

FloatArray = npt.NDArray[np.float64]

#: Around a keystroke's stages, how much rest to show before and after (fraction of its length).
STAGE_MARGIN = 0.05
#: Stage shading: light colours apart from the traces' (grey, blue, red).
STAGE_COLOURS = ("#fdf1c7", "#d9f0d3", "#e5d8f0", "#fcdcc5", "#d5ecf2")
#: Above this many settings per panel the silent map stops printing counts (they would collide).
MAX_LABELLED_SETTINGS = 40


def velocity_vs_speed(trials: pd.DataFrame) -> Figure:
    """On-velocity against arm down speed, one series per vacuum level."""
    fig = Figure(figsize=(6, 4))
    ax = fig.add_subplot()
    sounded = trials.dropna(subset=["on_velocity"])
    for vacuum, group in sounded.groupby("vacuum_kpa"):
        ax.plot(group["down_velocity_mps"], group["on_velocity"], "o", ms=3, label=f"{vacuum:g} kPa")
    ax.set_xlabel("arm down velocity (m/s)")
    ax.set_ylabel("MIDI on-velocity")
    if not sounded.empty:
        ax.legend(fontsize=7)
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
    fig = Figure(figsize=(min(3.2 * len(depths), 12) + 1.0, 3.6))
    axes = fig.subplots(1, len(depths), sharex=True, sharey=True, squeeze=False)[0]
    scatter = None
    for ax, depth in zip(axes, depths, strict=True):
        rows = table if math.isnan(depth) else table[table["depth_m"] == depth]
        most = max(float(table["keystrokes"].max()), 1.0) if not table.empty else 1.0
        size = (30.0 + 170.0 * rows["keystrokes"].to_numpy(float) / most) if not rows.empty else np.zeros(0)
        scatter = ax.scatter(rows["down_velocity_mps"], rows["vacuum_kpa"], c=rows["silent_fraction"], s=size,
                             cmap="coolwarm", vmin=0.0, vmax=1.0, edgecolors="k", linewidths=0.5)
        if 0 < len(rows) <= MAX_LABELLED_SETTINGS:
            for v, p, k, n in rows[["down_velocity_mps", "vacuum_kpa", "silent", "keystrokes"]].to_numpy(float):
                ax.annotate(f"{k:.0f}/{n:.0f}", (v, p), xytext=(0, 9), textcoords="offset points",
                            ha="center", fontsize=7)
        title = "" if table.empty else "all depths" if math.isnan(depth) else (
            "depth not recorded" if depth < 0 else f"depth {1e3 * depth:g} mm")
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("arm down velocity (m/s)")
        ax.margins(0.15)
    axes[0].set_ylabel("vacuum (kPa)")
    if table.empty:
        axes[0].set_axis_off()
        axes[0].text(0.5, 0.5, "no MIDI outcome recorded", transform=axes[0].transAxes, ha="center", va="center")
    elif scatter is not None:
        fig.colorbar(scatter, ax=list(axes), label="silent fraction (labels: silent/keystrokes)", fraction=0.05)
    return fig


def coverage(trials: pd.DataFrame, columns: list[str]) -> Figure:
    """Histogram of each varying parameter (what the run covered)."""
    fig = Figure(figsize=(3 * max(len(columns), 1), 2.6))
    for i, name in enumerate(columns):
        ax = fig.add_subplot(1, max(len(columns), 1), i + 1)
        ax.hist(trials[name].dropna(), bins=15)
        ax.set_xlabel(name, fontsize=8)
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


def _stage_edges(t: FloatArray, x0: FloatArray, x1: FloatArray, x2: FloatArray, distance_m: float) -> FloatArray:
    """The five stages' boundaries of traces that are relative to rest.

    `segment_keystroke` takes each trace's rest level from its first 5 % of samples, but a sweep's
    traces start at motion start (the arm is already moving), which would move the rest level
    into the approach. The traces here are relative to rest already, so that rest is shown to
    it explicitly: zeros for the length of 5 % of the trace before the first sample.
    """
    pad = t.size // 19 + 3
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    tt = np.r_[t[0] - dt * np.arange(pad, 0, -1), t]
    rest = np.zeros(pad)
    found = segment_keystroke(tt, np.r_[rest, x2], x0_m=np.r_[rest, x0], x1_m=np.r_[rest, x1],
                              distance_m=distance_m if distance_m > 0 else None)
    return np.asarray(np.maximum(found.boundaries_s, t[0]), dtype=np.float64)


def stages(t_s: FloatArray, x0: FloatArray, x1: FloatArray, x2: FloatArray,
           x1_model: FloatArray | None, x2_model: FloatArray | None, *, distance_m: float = 0.0) -> Figure:
    """One keystroke, measured (solid) and model (dashed), with the study's five stages shaded.

    Top: arm, fingertip and key surface in one frame — depth below the key's rest surface, so
    the fingertip starts `distance_m` above it and touches where its line meets the key's.
    Bottom: the key alone, at its own scale. Stage names are in the legend below the axes; the
    model traces end where the model does (lift-off: NaN from there, see `model_window`).
    """
    t = np.asarray(t_s, dtype=np.float64)
    edges = _stage_edges(t, x0, x1, x2, distance_m)
    lo, hi = _window(t, edges, x0, x2)
    show = (t >= lo) & (t <= hi)
    fig = Figure(figsize=(8, 6.2))
    top, bottom = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 2]})
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


def bode(params: MSDParams, levels_kpa: list[float]) -> Figure:
    """|X2/X0| and phase of the model at the given vacuum levels."""
    fig = Figure(figsize=(6, 5))
    mag, ph = fig.add_subplot(2, 1, 1), fig.add_subplot(2, 1, 2)
    f = np.geomspace(0.5, 200, 400)
    for p in levels_kpa:
        gain, phase = frequency_response(params.at(p), f)
        mag.loglog(f, gain, label=f"{p:g} kPa")
        ph.semilogx(f, np.degrees(phase))
    mag.set_ylabel("|X2/X0|")
    ph.set_ylabel("phase (deg)")
    ph.set_xlabel("f (Hz)")
    mag.legend(fontsize=7)
    return fig


def residuals(t_s: FloatArray, residual_m: FloatArray) -> Figure:
    """Key-trajectory residuals (measured − model) of every keystroke."""
    fig = Figure(figsize=(6, 3))
    ax = fig.add_subplot()
    for row in residual_m:
        ax.plot(t_s, 1e3 * row, lw=0.6, alpha=0.6)
    measured = np.flatnonzero(np.isfinite(residual_m).any(axis=0))
    if measured.size:
        ax.set_xlim(float(t_s[measured[0]]), float(t_s[measured[-1]]))
    ax.set_xlabel("time since motion start (s)")
    ax.set_ylabel("x2 residual (mm)")
    return fig
