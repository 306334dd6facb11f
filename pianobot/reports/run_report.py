"""`pianobot report`: one self-contained HTML page about runs (and a model) — figures embedded."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from pianobot.analysis.identify import simulate_batch
from pianobot.analysis.identify_run import load_batch
from pianobot.analysis.predictors import INPUT_COLUMNS
from pianobot.errors import InputError
from pianobot.physics.model import read_model_file
from pianobot.physics.msd import MSDParams
from pianobot.reports import figures
from pianobot.reports.html import (
    Section,
    figure_html,
    mapping_table_html,
    paragraph,
    table_html,
    write_page,
)
from pianobot.store import load_run, rig_summary


def sound_by_level(trials: pd.DataFrame) -> pd.DataFrame:
    """Keystrokes, sounded, silent and on-velocity range per vacuum level."""
    rows = []
    for vacuum, group in trials.groupby(trials["vacuum_kpa"].fillna(np.nan), dropna=False):
        on = group["on_velocity"].astype(float)
        rows.append({"vacuum_kpa": vacuum, "keystrokes": len(group), "sounded": int(on.notna().sum()),
                     "silent": int((group["status"] == "silent").sum()),
                     "on_velocity_min": on.min(), "on_velocity_median": on.median(), "on_velocity_max": on.max()})
    return pd.DataFrame(rows)


def build_run_report(run_ids: Sequence[str], data_dir: Path, out: Path, *, model_file: Path | None = None,
                     cv_table: pd.DataFrame | None = None) -> Path:
    """Write the report for `run_ids` to `out` and return its path."""
    if not run_ids:
        raise InputError("give at least one run", "report")
    runs = [load_run(r, data_dir) for r in run_ids]
    trials = pd.concat([r.trials for r in runs], ignore_index=True)
    if trials.empty:
        raise InputError("the runs have no trials", ", ".join(run_ids))
    # Imported runs lack some columns (a mocap take has no MIDI, old logs no start times).
    for column in ("on_velocity", "vacuum_kpa", "down_velocity_mps", "status"):
        if column not in trials:
            trials[column] = np.nan
    params, intervals, provenance = MSDParams(), None, None
    if model_file is not None:
        mf = read_model_file(model_file)
        params, intervals, provenance = mf.model.msd, mf.intervals, mf.provenance

    sections = []
    prov = Section("Run provenance")
    for run in runs:
        meta = run.meta
        keys = ("run_id", "name", "kind", "status", "pianobot_version", "git_commit", "start_utc", "end_utc", "seed")
        provenance_rows = [(k, meta.get(k)) for k in keys] + [("rig", rig_summary(meta))]
        prov.add(mapping_table_html(provenance_rows, caption=run.run_id))
    sections.append(prov)

    varying = [c for c in INPUT_COLUMNS if c in trials and trials[c].nunique() > 1]
    cov = Section("Parameter coverage")
    cov.add(table_html(trials[varying + ["on_velocity"]].describe().reset_index(), caption="summary"))
    if varying:
        cov.add(figure_html(figures.coverage(trials, varying), "distribution of each varied parameter"))
    sections.append(cov)

    out_sec = Section("Sound")
    out_sec.add(table_html(sound_by_level(trials), caption="keystrokes per vacuum level"))
    out_sec.add(figure_html(figures.velocity_vs_speed(trials), "on-velocity vs arm speed per vacuum level"))
    out_sec.add(figure_html(figures.silent_map(trials), "silent keystrokes per setting (silent/keystrokes)"))
    sections.append(out_sec)

    traj = Section("Keystroke stages: measured vs model")
    try:
        batch, _ = load_batch(run_ids, data_dir)
    except InputError as exc:
        traj.add(paragraph(f"No trajectories: {exc.message}.", note=True))
    else:
        x1m, x2m = simulate_batch(batch, params)
        i = int(np.nanargmax(np.nanmax(np.nan_to_num(batch.x2_m, nan=-np.inf), axis=1)))
        traj.add(figure_html(
            figures.stages(batch.row_times_s(i), batch.x0_m[i], batch.x1_m[i], batch.x2_m[i], x1m[i], x2m[i],
                           distance_m=float(batch.distance_m[i])),
            f"keystroke {batch.trial_id[i]} (the deepest key travel): measured (solid) and model (dashed); "
            "the model is driven by the measured arm trace, with the fingertip starting "
            f"{1e3 * batch.distance_m[i]:g} mm above the key"))
        traj.add(figure_html(figures.residuals(batch.t_s, batch.x2_m - x2m), "x2 residuals, all keystrokes"))
    sections.append(traj)

    model_sec = Section("Model")
    levels = sorted({float(v) for v in trials["vacuum_kpa"].dropna()}) or [0.0]
    model_sec.add(figure_html(figures.bode(params, levels), "Bode plot of x2/x0"))
    rows = [{"name": k, "value": v} for k, v in params.to_dict().items() if k != "k1_table"]
    model_sec.add(table_html(pd.DataFrame(rows), caption="model parameters"))
    if intervals:
        irows = [{"name": k, "value": v.get("value"), "ci95_lo": (v.get("ci95") or [None, None])[0],
                  "ci95_hi": (v.get("ci95") or [None, None])[1]} for k, v in intervals.items()]
        model_sec.add(table_html(pd.DataFrame(irows), caption="identified parameters with 95 % intervals"))
    for key, caption in (("damping_check", "damping cross-check (logarithmic decrement of free key ringing)"),
                         ("readout", "identified piano readout (trigger depth, velocity map)")):
        found = (provenance or {}).get(key)
        if isinstance(found, dict):
            model_sec.add(mapping_table_html(sorted(found.items()), caption=caption))
    sections.append(model_sec)

    if cv_table is not None:
        sections.append(Section("Model comparison").add(table_html(cv_table, caption="grouped cross-validation")))
    return write_page(out, "pianobot report", sections, subtitle=json.dumps(list(run_ids)))
