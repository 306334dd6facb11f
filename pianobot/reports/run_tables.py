"""The run report's tables: provenance, coverage, sound per vacuum level, model parameters.

Each returns a DataFrame ready to show (headings with units, lengths in mm), so the HTML and
any other front end print the same numbers.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from datetime import datetime
from pathlib import PurePath
from typing import Any

import numpy as np
import pandas as pd

from pianobot.analysis.learn.predictors import INPUT_COLUMNS
from pianobot.durations import format_duration
from pianobot.physics.msd import MSDParams
from pianobot.reports.style import quantity
from pianobot.store import rig_summary, software_summary

#: Model parameters as a person reads them: name, symbol, unit (stiffness stays N/m, as published).
MODEL_PARAMETER_LABELS: dict[str, tuple[str, str]] = {
    "m1_kg": ("fingertip mass m1", "kg"),
    "m2_kg": ("key mass m2", "kg"),
    "k1_a_npm": ("finger stiffness at 0 kPa, k1 = a + b·|p|: a", "N/m"),
    "k1_b_npm_per_kpa": ("finger stiffness per kPa of vacuum: b", "N/m/kPa"),
    "c1_nspm": ("finger damping c1", "N·s/m"),
    "k2_npm": ("key spring k2", "N/m"),
    "c2_nspm": ("key damping c2", "N·s/m"),
    "k0_npm": ("arm–fingertip stiffness k0 (blank: = k1)", "N/m"),
    "c0_nspm": ("arm–fingertip damping c0 (blank: = c1)", "N·s/m"),
    "k0_over_k1": ("arm–fingertip stiffness as a share of the finger's, k0/k1", "1"),
    "c0_over_c1": ("arm–fingertip damping as a share of the finger's, c0/c1", "1"),
}
#: A coupling given as a share of the finger's (`k0_over_k1`) leaves k0 itself blank: not shown.
_SHARE_OF = {"k0_npm": "k0_over_k1", "c0_nspm": "c0_over_c1"}


def parse_utc(text: Any) -> datetime | None:
    """`2026-11-24T10:41:10.851Z` → datetime, None when absent or unreadable."""
    if not isinstance(text, str) or not text:
        return None
    try:
        return datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        return None


def day(when: datetime | None) -> str:
    """`24 Nov 2026` (or `?`)."""
    return "?" if when is None else f"{when.day} {when:%b %Y}"


def _rig(meta: Mapping[str, Any]) -> str:
    rig = meta.get("rig")
    if isinstance(rig, dict) and rig.get("mixed"):
        return rig_summary(dict(meta))  # a resume ran on another rig (--rig-override): say so
    if isinstance(rig, dict):
        found = rig.get("spec")
        spec: dict[str, Any] = found if isinstance(found, dict) else {}
        kind = spec.get("kind") or rig.get("kind") or "?"
        name = {"sim": "simulated rig", "ur5": "UR5 lab rig"}.get(str(kind), str(kind))
        where = rig.get("file")
        return name if where in (None, "sim", kind) else f"{name} ({PurePath(str(where)).name})"
    source = meta.get("source")
    if isinstance(source, dict):
        return f"imported {source.get('format', 'data')}"
    return "?" if rig is None else str(rig)


def _spec(meta: Mapping[str, Any]) -> str:
    spec = meta.get("spec")
    sha = str(meta.get("spec_sha256") or "")[:12]
    if isinstance(spec, dict) and spec.get("path"):
        return f"{PurePath(str(spec['path'])).name} (sha256 {sha})" if sha else PurePath(str(spec["path"])).name
    source = meta.get("source")
    if isinstance(source, dict) and source.get("file"):
        digest = str(source.get("sha256") or "")[:12]
        return f"{source['file']} (sha256 {digest})" if digest else str(source["file"])
    return "-"


def provenance(meta: Mapping[str, Any], trials: pd.DataFrame) -> list[tuple[str, str]]:
    """Where one run came from: rig, spec, lab time, software, dates."""
    planned = meta.get("trials_planned")
    counted = f"{len(trials)}" + (f" of {planned} planned" if planned else "")
    lab = meta.get("lab_time_s")
    start, end = parse_utc(meta.get("start_utc")), parse_utc(meta.get("end_utc"))
    when = "?" if start is None else f"{start:%Y-%m-%d %H:%M} UTC"
    if start is not None and end is not None:
        when += f" to {end:%H:%M} UTC" if end.date() == start.date() else f" to {end:%Y-%m-%d %H:%M} UTC"
    return [
        ("run", str(meta.get("run_id", "?"))),
        ("name / kind / status", f"{meta.get('name', '?')} / {meta.get('kind', '?')} / {meta.get('status', '?')}"),
        ("recorded", when),
        ("rig", _rig(meta)),
        ("spec or source file", _spec(meta)),
        ("keystrokes", counted),
        ("lab time", format_duration(float(lab)) if isinstance(lab, int | float) else "- (not recorded)"),
        ("seed", "-" if meta.get("seed") is None else str(meta.get("seed"))),
        ("software", software_summary(dict(meta))),
    ]


def coverage_table(trials: pd.DataFrame) -> pd.DataFrame:
    """One row per press parameter: varied or fixed, range and number of distinct levels."""
    rows = []
    for name in INPUT_COLUMNS:
        if name not in trials:
            continue
        values = pd.to_numeric(trials[name], errors="coerce").dropna()
        if values.empty:
            continue
        q = quantity(name)
        shown = q.shown(values.astype(float))
        levels = int(values.round(9).nunique())
        rows.append({
            "parameter": q.label, "unit": q.unit or "-",
            "varied": "varied" if levels > 1 else "fixed",
            "min": float(shown.min()), "max": float(shown.max()), "levels": levels,
            "keystrokes": int(values.size),
        })
    return pd.DataFrame(rows, columns=["parameter", "unit", "varied", "min", "max", "levels", "keystrokes"])


def varied_columns(trials: pd.DataFrame) -> list[str]:
    """Press parameters that take more than one value."""
    return [c for c in INPUT_COLUMNS if c in trials and pd.to_numeric(trials[c], errors="coerce").nunique() > 1]


def sound_by_level(trials: pd.DataFrame) -> pd.DataFrame:
    """Keystrokes, sounded, silent and on-velocity range per vacuum level."""
    rows = []
    for vacuum, group in trials.groupby(trials["vacuum_kpa"].fillna(np.nan), dropna=False):
        on = group["on_velocity"].astype(float)
        silent = int((group["status"] == "silent").sum())
        rows.append({
            "vacuum (kPa)": vacuum, "keystrokes": len(group), "sounded": int(on.notna().sum()),
            "silent (%)": 100.0 * silent / len(group) if len(group) else math.nan,
            "on-velocity min": on.min(), "median": on.median(), "max": on.max(),
        })
    return pd.DataFrame(rows)


def parameter_table(params: MSDParams, intervals: Mapping[str, Any] | None) -> pd.DataFrame:
    """The model's parameters with units, and 95 % intervals where the model file has them."""
    rows = []
    values = params.to_dict()
    for key, value in values.items():
        if key == "k1_table":
            for vacuum, k1 in value:
                # Stored as a magnitude (40); read, and keyed in the intervals, as the gauge −40 kPa.
                gauge = -abs(float(vacuum)) or 0.0
                rows.append(_parameter_row(f"k1_npm@{gauge:g}kPa", f"finger stiffness k1 at {gauge:g} kPa",
                                           "N/m", k1, intervals))
            continue
        if value is None and values.get(_SHARE_OF.get(key, "")) is not None:
            continue  # "blank: = k1" would say the opposite of the share given below
        label, unit = MODEL_PARAMETER_LABELS.get(key, (key, quantity(key).unit))
        rows.append(_parameter_row(key, label, unit, value, intervals))
    return pd.DataFrame(rows)


def _parameter_row(key: str, label: str, unit: str, value: Any,
                   intervals: Mapping[str, Any] | None) -> dict[str, Any]:
    found = (intervals or {}).get(key)
    lo = hi = math.nan
    if isinstance(found, dict) and isinstance(found.get("ci95"), Sequence) and len(found["ci95"]) == 2:
        lo, hi = (math.nan if v is None else float(v) for v in found["ci95"])
    return {"parameter": label, "value": value, "unit": unit, "95 % low": lo, "95 % high": hi}


def cv_display(cv_table: pd.DataFrame) -> pd.DataFrame:
    """The grouped-CV table with units in its headings (hold in ms, silence in %)."""
    frame = cv_table.copy()
    shown = pd.DataFrame({"model": frame["model"].replace({"mean": "mean (baseline)"})})
    for column, heading, scale in (("rmse", "on-velocity RMSE", 1.0), ("mae", "on-velocity MAE", 1.0),
                                   ("r2", "R²", 1.0), ("hold_rmse_s", "hold RMSE (ms)", 1e3),
                                   ("silent_accuracy", "silence right (%)", 100.0),
                                   ("latency_ms", "predict (ms)", 1.0), ("fit_s", "fit (s)", 1.0)):
        if column in frame:
            shown[heading] = pd.to_numeric(frame[column], errors="coerce") * scale
    return shown
