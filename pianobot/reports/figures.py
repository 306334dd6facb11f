"""The run report's figures (matplotlib, Agg): each function takes data and returns a Figure."""

from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from pianobot.analysis.segment import STAGE_NAMES, segment_keystroke
from pianobot.physics.msd import MSDParams, frequency_response


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


def silent_map(trials: pd.DataFrame) -> Figure:
    """Silent (x) and sounded (o) keystrokes over down speed and vacuum."""
    fig = Figure(figsize=(6, 4))
    ax = fig.add_subplot()
    silent = trials["on_velocity"].isna()
    ax.plot(trials.loc[~silent, "down_velocity_mps"], trials.loc[~silent, "vacuum_kpa"], "o", ms=4, label="sounded")
    ax.plot(trials.loc[silent, "down_velocity_mps"], trials.loc[silent, "vacuum_kpa"], "x", ms=5, label="silent")
    ax.set_xlabel("arm down velocity (m/s)")
    ax.set_ylabel("vacuum (kPa)")
    ax.legend(fontsize=7)
    return fig


def coverage(trials: pd.DataFrame, columns: list[str]) -> Figure:
    """Histogram of each varying parameter (what the run covered)."""
    fig = Figure(figsize=(3 * max(len(columns), 1), 2.6))
    for i, name in enumerate(columns):
        ax = fig.add_subplot(1, max(len(columns), 1), i + 1)
        ax.hist(trials[name].dropna(), bins=15)
        ax.set_xlabel(name, fontsize=8)
    return fig


def stages(t_s: np.ndarray, x0: np.ndarray, x1: np.ndarray, x2: np.ndarray,
           x1_model: np.ndarray | None, x2_model: np.ndarray | None) -> Figure:
    """Measured (and model) traces of one keystroke with the five stages shaded."""
    fig = Figure(figsize=(7, 4))
    ax = fig.add_subplot()
    ax.plot(t_s, 1e3 * x0, "k-", lw=1, label="x0 arm")
    ax.plot(t_s, 1e3 * x1, "b-", lw=1, label="x1 fingertip")
    ax.plot(t_s, 1e3 * x2, "r-", lw=1, label="x2 key")
    if x1_model is not None and x2_model is not None:
        ax.plot(t_s, 1e3 * x1_model, "b--", lw=1, label="x1 model")
        ax.plot(t_s, 1e3 * x2_model, "r--", lw=1, label="x2 model")
    edges = segment_keystroke(t_s, x2, x0_m=x0, x1_m=x1).boundaries_s
    for i, name in enumerate(STAGE_NAMES):
        if np.isfinite(edges[i]) and np.isfinite(edges[i + 1]):
            ax.axvspan(edges[i], edges[i + 1], alpha=0.08 * (1 + i % 2), color=f"C{i}")
            ax.text(0.5 * (edges[i] + edges[i + 1]), ax.get_ylim()[1], name, fontsize=7, ha="center", va="top")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("displacement (mm, down +)")
    ax.legend(fontsize=7)
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


def residuals(t_s: np.ndarray, residual_m: np.ndarray) -> Figure:
    """Key-trajectory residuals (measured − model) of every keystroke."""
    fig = Figure(figsize=(6, 3))
    ax = fig.add_subplot()
    for row in residual_m:
        ax.plot(t_s, 1e3 * row, lw=0.6, alpha=0.6)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("x2 residual (mm)")
    return fig
