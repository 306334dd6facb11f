"""The report of a play run: one self-contained HTML page beside the performance (report.html).

What was played and how well (strict and tempo-relative scores, the piano roll), at which tempo
and why (written, fastest feasible, played, the notes that limit it), what the warm-up played
and learned (its keystrokes, the fitted maps, the held-out error of each model kind), and every
note: target, outcome, onset and velocity error, status and the planner's reason.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pandas as pd

from pianobot.io.midifile import Note
from pianobot.play.figure import piano_roll_figure, warmup_fit_figure
from pianobot.play.perform import Performance
from pianobot.play.score import Score
from pianobot.play.song_plan import SongPlan
from pianobot.play.warmup import WarmUp
from pianobot.reports.html import (
    Section,
    figure_html,
    mapping_table_html,
    paragraph,
    table_html,
    write_page,
)

NOTE_COLUMNS = ("pitch", "onset_s", "target_velocity", "played_velocity", "onset_error_ms", "velocity_error",
                "status", "reason")


def _fmt(value: Any) -> Any:
    """Numbers to four significant digits (lists and dicts of them too) for the mapping tables;
    "n/a" where there was nothing to measure (no note heard, no stroke held out)."""
    if isinstance(value, float):
        return f"{value:.4g}" if math.isfinite(value) else "n/a"
    if isinstance(value, list | tuple):
        return ", ".join(str(_fmt(v)) for v in value)
    if isinstance(value, dict):
        return "; ".join(f"{k}: {_fmt(v)}" for k, v in value.items())
    return value


def _rows(items: Any) -> list[tuple[str, Any]]:
    return [(str(k), _fmt(v)) for k, v in items]


def write_play_report(path: Path, *, performance: Performance, plan: SongPlan, score: Score, target: list[Note],
                      warmup: WarmUp | None, model: str, title: str) -> Path:
    """Write the play run's report to `path` (see the module doc)."""
    sections = [_performance(performance, plan, score, target, title), _tempo(plan)]
    sections.append(_warmup(warmup) if warmup is not None else Section("Warm-up").add(paragraph(
        f"No warm-up: the song was planned with the {model} as it is.", note=True)))
    sections.append(_notes(plan, score))
    return write_page(path, f"pianobot play: {performance.run_id}", sections,
                      subtitle=f"{plan.planner} planner, {model}")


def _performance(performance: Performance, plan: SongPlan, score: Score, target: list[Note], title: str) -> Section:
    section = Section("Performance")
    scores = score.to_dict()
    rows: list[tuple[str, Any]] = [
        ("F1 (50 ms, on the clock of the tempo played)", scores["f1"]),
        ("onset RMS (ms)", scores["onset_rms_ms"]), ("onset mean (ms)", scores["onset_mean_ms"]),
        ("velocity MAE (mapped targets)", scores["velocity_mae"]),
        ("velocity MAE (written velocities)", scores["velocity_mae_unmapped"]),
        ("duration MAE (ms)", scores["duration_mae_ms"]),
        ("notes target / played / paired loosely", f"{score.notes_target} / {score.notes_played} / {score.notes_paired}"),
        *((f"tempo-relative {k}", v) for k, v in scores["tempo_relative"].items()),
        *((f"notes {k}", v) for k, v in scores["note_status"].items()),
        ("run status", f"{performance.status}{'' if not performance.reason else ': ' + performance.reason}"),
    ]
    section.add(mapping_table_html(_rows(rows), caption="scores"))
    section.add(figure_html(piano_roll_figure(target, performance.notes, title=title,
                                              status=list(score.per_note["status"])),
                            "piano roll: target notes outlined by what happened to them, played notes filled "
                            "(darker = louder), on the clock of the tempo played"))
    return section


def _tempo(plan: SongPlan) -> Section:
    section = Section("Tempo and plan")
    summary = plan.summary()
    tempo = summary["tempo"] or {}
    rows: list[tuple[str, Any]] = [(k.replace("_", " "), v) for k, v in tempo.items()]
    rows += [("planned / skipped / late", f"{summary['planned']} / {summary['skipped']} / {summary['late']}"),
             ("mapping", (summary["dynamics"] or {}).get("text", "none")),
             ("vacuum levels used (kPa)", summary["vacuum_levels_used_kpa"])]
    rows += [(f"stroke {k}", v) for k, v in (summary["geometry"] or {}).items()]
    section.add(mapping_table_html(_rows(rows), caption="tempo, stroke and loudness mapping"))
    for line in plan.warnings:
        section.add(paragraph(line, note=True))
    return section


def _warmup(warm: WarmUp) -> Section:
    section = Section("Warm-up")
    summary = warm.summary()
    fits = summary.pop("fit", {})
    section.add(mapping_table_html(_rows((k.replace("_", " "), v) for k, v in summary.items()),
                                   caption="what it played"))
    section.add(table_html(pd.DataFrame([{"model kind": k, **v} for k, v in fits.items()]),
                           caption="each model kind's error on keystrokes held out of its fit"))
    section.add(figure_html(warmup_fit_figure(warm.trials, warm.predictor),
                            "the warm-up's keystrokes (dots; x: silent) and the maps fitted to them (lines)"))
    columns = [c for c in ("vacuum_kpa", "note", "down_velocity_mps", "approach_m", "hold_s", "status",
                           "on_velocity", "t_on_s", "midi_hold_s") if c in warm.trials]
    section.add(table_html(warm.trials[columns], caption="the warm-up keystrokes"))
    return section


def _notes(plan: SongPlan, score: Score) -> Section:
    notes = score.per_note.assign(onset_error_ms=score.per_note["onset_error_s"] * 1e3,
                                  reason=plan.notes["reason"].to_numpy())
    return Section("Notes").add(table_html(notes[list(NOTE_COLUMNS)].reset_index(names="note"),
                                           caption="every note: target, outcome, errors, status, the planner's reason"))
