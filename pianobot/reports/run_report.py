"""`pianobot report`: one self-contained HTML page about runs (and a model), read like a paper.

Title from the runs' names and date; provenance (rig, spec, lab time, software); coverage as a
parameter table and labelled histograms; sound per vacuum level; one keystroke's stages and the
residuals of all of them per stage; the model's response and parameters. Every figure has a
caption and a "what this shows" line; lengths are in mm throughout.
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pandas as pd

import pianobot
from pianobot.analysis.greybox.load import load_batch
from pianobot.analysis.identify.fit import simulate_batch
from pianobot.errors import InputError
from pianobot.physics.model import read_model_file
from pianobot.physics.msd import MSDParams
from pianobot.progress import NO_PROGRESS, Progress
from pianobot.reports import figures
from pianobot.reports.html import (
    Section,
    figure_html,
    mapping_table_html,
    paragraph,
    table_html,
    write_page,
)
from pianobot.reports.run_tables import (
    coverage_table,
    cv_display,
    day,
    parameter_table,
    parse_utc,
    provenance,
    sound_by_level,
    varied_columns,
)
from pianobot.reports.stage_residuals import stage_residuals
from pianobot.store import Run, load_runs, unfinished_note

__all__ = ["build_run_report", "sound_by_level"]


def report_title(runs: Sequence[Run]) -> str:
    """`soft-lhs — 24 Nov 2026`; several runs are listed by name, with the span of their dates."""
    names = list(dict.fromkeys(str(r.meta.get("name") or r.run_id) for r in runs))
    shown = ", ".join(names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")
    dates = sorted(d for d in (parse_utc(r.meta.get("start_utc")) for r in runs) if d is not None)
    if not dates:
        return shown
    first, last = day(dates[0]), day(dates[-1])
    return f"{shown} — {first}" if first == last else f"{shown} — {first} to {last}"


def _subtitle(runs: Sequence[Run], trials: pd.DataFrame) -> str:
    kinds = sorted({str(r.meta.get("kind", "?")) for r in runs})
    now = datetime.now(UTC)
    return (f"Run report: {len(trials)} keystrokes from {len(runs)} run{'s' if len(runs) > 1 else ''} "
            f"({', '.join(kinds)}). Made {now:%Y-%m-%d %H:%M} UTC by pianobot {pianobot.__version__}.")


def _provenance_section(runs: Sequence[Run]) -> Section:
    section = Section("Provenance")
    for run in runs:  # as the terminal says it: the page is read later, without the terminal
        note = unfinished_note(run)
        if note is not None:
            section.add(paragraph(f"Warning: {note}", warning=True))
    tables = [provenance(r.meta, r.trials) for r in runs]
    if len(runs) == 1:
        section.add(mapping_table_html(tables[0]))
    else:
        frame = pd.DataFrame({r.run_id: dict(t) for r, t in zip(runs, tables, strict=True)})
        frame.index.name = ""
        section.add(table_html(frame.drop(index="run"), index=True))
    return section


def _coverage_section(trials: pd.DataFrame) -> Section:
    section = Section("Parameter coverage")
    section.add(table_html(coverage_table(trials), float_format=".4g",
                           caption="press parameters: range and number of distinct levels"))
    varied = varied_columns(trials)
    if varied:
        section.add(figure_html(
            figures.coverage(trials, varied), "Keystrokes per value of each varied press parameter.",
            shows="how evenly the run sampled each parameter; a gap or a pile-up is a region any "
                  "model fitted to these runs knows little about."))
    return section


def _sound_section(trials: pd.DataFrame) -> Section:
    section = Section("Sound")
    section.add(table_html(sound_by_level(trials), float_format=".3g", caption="keystrokes per vacuum level"))
    section.add(figure_html(
        figures.velocity_vs_speed(trials), "MIDI on-velocity against arm down velocity, per vacuum level.",
        shows="how loudness follows arm speed; a stiffer (more evacuated) finger passes more of the "
              "arm's speed to the key, so its points lie higher."))
    section.add(figure_html(
        figures.silent_map(trials), "Silent keystrokes per setting (labels: silent/keystrokes).",
        shows="where the key was pressed but never sounded: slow, soft presses lose the key's "
              "momentum before the piano's trigger."))
    return section


def _stages_section(run_ids: Sequence[str], data_dir: Path, params: MSDParams) -> Section:
    section = Section("Keystroke stages: measured and model")
    try:
        batch, _ = load_batch(run_ids, data_dir)
    except InputError as exc:
        text = exc.message.replace("; give --vacuum-kpa", " (import it with --vacuum-kpa to see its stages)")
        return section.add(paragraph(f"No trajectories: {text}.", note=True))
    x1m, x2m = simulate_batch(batch, params)
    i = int(np.nanargmax(np.nanmax(np.nan_to_num(batch.x2_m, nan=-np.inf), axis=1)))
    section.add(figure_html(
        figures.stages(batch.row_times_s(i), batch.x0_m[i], batch.x1_m[i], batch.x2_m[i], x1m[i], x2m[i],
                       distance_m=float(batch.distance_m[i])),
        f"Keystroke {batch.trial_id[i]}, the deepest key travel of the runs: measured (solid) and "
        f"model (dashed), the study's five stages shaded.",
        shows=f"one keystroke as the model sees it: driven by the measured arm trace, the fingertip "
              f"starts {1e3 * batch.distance_m[i]:g} mm above the key, touches it, and carries it down "
              "to the bottom of its travel and back."))
    found = stage_residuals([batch.row_times_s(k) for k in range(len(batch.trial_id))],
                            batch.x0_m, batch.x1_m, batch.x2_m, x2m, batch.distance_m)
    section.add(figure_html(
        figures.residual_band(found),
        f"Key residual (measured − model) over {len(batch.trial_id)} keystrokes, stage by stage: "
        "median and 10–90 % band.",
        shows="where in a keystroke the model misses and by how much; a band away from zero in one "
              "stage points at physics the model lacks there (e.g. the keybed at the bottom)."))
    table = found.table.rename(columns={
        "median_duration_s": "median duration (s)", "median_residual_m": "median residual (mm)",
        "rms_residual_m": "RMS residual (mm)", "p90_abs_residual_m": "90 % of |residual| below (mm)"})
    for column in ("median residual (mm)", "RMS residual (mm)", "90 % of |residual| below (mm)"):
        table[column] = 1e3 * table[column]
    section.add(table_html(table, float_format=".3g", caption="key residual per stage"))
    return section


def _model_section(trials: pd.DataFrame, params: MSDParams, intervals: dict[str, object] | None,
                   model_provenance: dict[str, object] | None, model_name: str) -> Section:
    section = Section("Model")
    levels = sorted({float(v) for v in trials["vacuum_kpa"].dropna()}) or [0.0]
    section.add(figure_html(
        figures.bode(params, levels), f"Response of the key to the arm, |X2/X0| and phase ({model_name}).",
        shows="at which frequency the finger–key system rings at each vacuum (the dots); the real "
              "key rings at about 7–11 Hz, and a stiffer finger moves the peak up."))
    section.add(table_html(parameter_table(params, intervals), float_format=".4g",
                           caption=f"parameters of the {model_name}"))
    for key, caption in (("damping_check", "damping cross-check (logarithmic decrement of free key ringing)"),
                         ("readout", "identified piano readout (trigger depth, velocity map)")):
        found = (model_provenance or {}).get(key)
        if isinstance(found, dict):
            section.add(mapping_table_html(sorted(found.items()), caption=caption))
    warnings = (model_provenance or {}).get("warnings")
    if isinstance(warnings, list):
        for warning in warnings:
            text = warning.get("message") if isinstance(warning, dict) else warning
            section.add(paragraph(f"Warning: {text}", warning=True))
    return section


def build_run_report(run_ids: Sequence[str], data_dir: Path, out: Path, *, model_file: Path | None = None,
                     cv_table: pd.DataFrame | None = None, progress: Progress = NO_PROGRESS) -> Path:
    """Write the report for `run_ids` to `out` and return its path."""
    if not run_ids:
        raise InputError("give at least one run", "report")
    with progress.task("report", total=6) as task:
        task.update(note="loading runs")
        runs = load_runs(run_ids, data_dir)
        trials = pd.concat([r.trials for r in runs], ignore_index=True)
        if trials.empty:
            raise InputError("the runs have no trials", ", ".join(run_ids))
        # Imported runs lack some columns (a mocap take has no MIDI, old logs no start times).
        for column in ("on_velocity", "vacuum_kpa", "down_velocity_mps", "status"):
            if column not in trials:
                trials[column] = np.nan
        params, intervals, model_prov, model_name = MSDParams(), None, None, "study's published model"
        if model_file is not None:
            mf = read_model_file(model_file)
            params, intervals, model_prov = mf.model.msd, mf.intervals, mf.provenance
            model_name = f"model {model_file.name}"
        task.advance(note="coverage")
        sections = [_provenance_section(runs), _coverage_section(trials)]
        task.advance(note="sound")
        sections.append(_sound_section(trials))
        task.advance(note="keystroke stages (simulating every keystroke)")
        sections.append(_stages_section(run_ids, data_dir, params))
        task.advance(note="model")
        sections.append(_model_section(trials, params, intervals, model_prov, model_name))
        if cv_table is not None:
            sections.append(Section("Model comparison").add(
                table_html(cv_display(cv_table), float_format=".3g",
                           caption="grouped cross-validation of on-velocity (sounded keystrokes)")))
        task.advance(note="writing")
        path = write_page(out, report_title(runs), sections, subtitle=_subtitle(runs, trials))
        task.advance()
    return path
