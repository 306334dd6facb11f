"""How every report figure and table reads: quantities with units, axis labels, figure style.

Shared by the run, discovery and play reports so they look alike. One length unit throughout:
millimetres (and mm/s, mm/s²) in text, tables and axes; data stay in SI on disk and are scaled
here, at the last moment. `quantity("depth_m")` knows a column's label, unit and scale;
`label_axes(ax, x, y)` writes "label (unit)" on both axes; `new_figure` gives every figure the
same size, fonts and grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from pianobot.analysis.plausibility import local_resonance_hz
from pianobot.physics.linear import frequency_response, peak_response
from pianobot.physics.msd import LinearParams
from pianobot.spec.parameters import PARAMETERS

#: Width of a report figure that spans the page, inches (pages are about 1,000 px at 100 dpi).
FULL_WIDTH_IN = 8.0


@dataclass(frozen=True)
class Quantity:
    """A physical quantity as shown to people: label, display unit and the scale from SI."""

    label: str
    unit: str = ""
    scale: float = 1.0

    @property
    def heading(self) -> str:
        """`pressing depth (mm)`; a unitless quantity is just its label."""
        return f"{self.label} ({self.unit})" if self.unit else self.label

    def shown(self, values: Any) -> Any:
        """SI values (scalar, array or Series) in the display unit."""
        return values * self.scale if self.scale != 1.0 else values


# Column names of the dataset (units in the names) → how they are shown.
QUANTITIES: dict[str, Quantity] = {
    **{p.name: Quantity(p.label, p.display_unit, p.display_scale) for p in PARAMETERS.values()},
    "on_velocity": Quantity("MIDI on-velocity", "1–127"),
    "off_velocity": Quantity("MIDI off-velocity", "1–127"),
    "t_on_s": Quantity("note-on after motion start", "ms", 1e3),
    "t_off_s": Quantity("note-off after motion start", "ms", 1e3),
    "midi_hold_s": Quantity("MIDI hold", "ms", 1e3),
    "key_speed_at_trigger_mps": Quantity("key speed at trigger", "mm/s", 1e3),
    "max_key_travel_m": Quantity("max key travel", "mm", 1e3),
    "x0_m": Quantity("arm x0", "mm", 1e3),
    "x1_m": Quantity("fingertip x1", "mm", 1e3),
    "x2_m": Quantity("key x2", "mm", 1e3),
    "t_s": Quantity("time", "s"),
}

# Unit suffixes of names not listed above: (suffix, display unit, scale).
_SUFFIXES = (
    ("_mps2", "mm/s²", 1e3), ("_mps", "mm/s", 1e3), ("_m", "mm", 1e3), ("_s", "s", 1.0),
    ("_kpa", "kPa", 1.0), ("_hz", "Hz", 1.0), ("_kg", "kg", 1.0), ("_npm", "N/m", 1.0),
    ("_nspm", "N·s/m", 1.0), ("_deg", "°", 1.0), ("_pct", "%", 1.0),
)


def quantity(name: str) -> Quantity:
    """How column `name` is shown; unknown names get their unit from the suffix."""
    if name in QUANTITIES:
        return QUANTITIES[name]
    for suffix, unit, scale in _SUFFIXES:
        if name.endswith(suffix):
            return Quantity(name[: -len(suffix)].replace("_", " "), unit, scale)
    return Quantity(name.replace("_", " "))


def display_frame(frame: pd.DataFrame, columns: dict[str, str] | None = None) -> pd.DataFrame:
    """A copy with numeric SI columns scaled to display units and headed `label (unit)`.

    Args:
        columns: optional overrides of the heading for some columns.
    """
    out = {}
    for name in frame.columns:
        q = quantity(str(name))
        series = frame[name]
        heading = (columns or {}).get(str(name), q.heading)
        out[heading] = q.shown(series) if pd.api.types.is_numeric_dtype(series) else series
    return pd.DataFrame(out)


def axis_label(what: str | Quantity) -> str:
    """`what` as an axis label: a Quantity's heading, or a string that already has its unit."""
    return what.heading if isinstance(what, Quantity) else what


def label_axes(ax: Axes, x: str | Quantity, y: str | Quantity) -> None:
    """Label both axes with their units: `label_axes(ax, quantity("depth_m"), "keystrokes")`."""
    ax.set_xlabel(axis_label(x))
    ax.set_ylabel(axis_label(y))


def new_figure(width_in: float = 6.0, height_in: float = 4.0) -> Figure:
    """A figure in the house style (sizes in inches; fonts sized for a page at 100 dpi)."""
    fig = Figure(figsize=(width_in, height_in), layout="constrained")
    fig.set_facecolor("white")
    return fig


def style_axes(ax: Axes) -> Axes:
    """Light grid behind the data, no top/right spines: the data stand out, the frame does not."""
    ax.grid(True, alpha=0.3, lw=0.6)
    ax.set_axisbelow(True)
    for side in ("top", "right"):
        ax.spines[side].set_visible(False)
    ax.tick_params(labelsize=8)
    ax.xaxis.label.set_fontsize(9)
    ax.yaxis.label.set_fontsize(9)
    return ax


def unlabelled_axes(fig: Figure) -> list[str]:
    """Axes of `fig` that show data but lack an x or y label (for tests and self-checks).

    Colour bars and axes switched off are skipped; of axes sharing an x axis, one label is
    enough (the bottom one carries it).
    """
    missing = []
    for i, ax in enumerate(fig.axes):
        if not ax.axison or ax.get_label() == "<colorbar>":
            continue
        shared_x = [a for a in ax.get_shared_x_axes().get_siblings(ax) if a is not ax]
        if not ax.get_xlabel() and not any(a.get_xlabel() for a in shared_x):
            missing.append(f"axes {i}: no x label")
        shared_y = [a for a in ax.get_shared_y_axes().get_siblings(ax) if a is not ax]
        if not ax.get_ylabel() and not any(a.get_ylabel() for a in shared_y):
            missing.append(f"axes {i}: no y label")
    return missing


def percentile_band(values: npt.NDArray[np.float64], lo_pct: float = 10.0,
                    hi_pct: float = 90.0) -> tuple[npt.NDArray[np.float64], ...]:
    """(median, low, high, count) over axis 0, ignoring NaN; all-NaN columns give NaN."""
    finite = np.isfinite(values)
    count = finite.sum(axis=0).astype(np.float64)
    out = []
    for q in (50.0, lo_pct, hi_pct):
        col = np.full(values.shape[1], np.nan)
        ok = count > 0
        if ok.any():
            col[ok] = np.nanpercentile(values[:, ok], q, axis=0)
        out.append(col)
    return out[0], out[1], out[2], count


def resonance_label(lp: LinearParams, name: str) -> tuple[str, float, float]:
    """Legend text and marker (Hz, gain; NaN: none) of a key response's resonance.

    A resonance weaker than the static response is still shown, and said to be so: the global
    peak alone would call it "0 Hz".
    """
    peak_hz, peak_gain = peak_response(lp)
    if peak_hz > 0:
        return f"{name}: peak {peak_hz:.1f} Hz", peak_hz, peak_gain
    hidden_hz = local_resonance_hz(lp)
    if math.isfinite(hidden_hz):
        gain, _ = frequency_response(lp, np.array([hidden_hz]))
        return f"{name}: {hidden_hz:.1f} Hz, below the static gain", hidden_hz, float(gain[0])
    return f"{name}: no resonance", math.nan, math.nan
