"""Importing an old keystroke log as a new run.

One trial per keystroke line (`keystroke_log.read_keystroke_log`). The log's MIDI clock restarts
with every script run (a *session*); the run clock stacks sessions 1 s apart so MIDI times stay
ordered, and `t_on_log_s`/`t_off_log_s` keep the log's own times. The logs never recorded when
motion started, so `t_start_s`, `t_on_s`, `t_off_s` (relative to motion start) are NaN.

The run's meta records the source (name, sha256), the layout or named-key mapping, the stated
conventions (note octave, finger), skipped lines, and how events were assigned (read size,
per-session constants, moved/unread/undecided counts, presses that belong to no logged
keystroke); the journal records the same summary. Each moved or doubtful trial carries its
evidence in `assignment_evidence`.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pianobot.io.keystroke_log import KeystrokeLog, read_keystroke_log
from pianobot.io.named_keys import DEFAULT_NOTE_OCTAVE
from pianobot.io.run_output import (
    ImportResult,
    file_sha256,
    jsonable,
    run_dir,
    trial_ids,
    write_run,
)
from pianobot.progress import NO_PROGRESS, Progress


def import_keystroke_log(
    path: Path | str,
    data_dir: Path | str,
    layout: str = "auto",
    *,
    columns: list[str] | None = None,
    layout_file: Path | str | None = None,
    finger: str | None = None,
    note_octave: int = DEFAULT_NOTE_OCTAVE,
    progress: Progress = NO_PROGRESS,
) -> ImportResult:
    """Import a dict-per-line keystroke log as a new run (arguments as `read_keystroke_log`)."""
    path, data_dir = Path(path), Path(data_dir)
    log = read_keystroke_log(
        path,
        layout,
        columns=columns,
        layout_file=layout_file,
        finger=finger,
        note_octave=note_octave,
        progress=progress,
    )
    sha = file_sha256(path)
    trials, midi = _tables(log, sha)
    skipped = tuple((s.line, s.reason) for s in log.skipped)
    summary = _summary(log, trials)
    meta = {
        "source": {"file": path.name, "sha256": sha, "format": "keystroke-log"},
        "layout": log.layout,
        "columns": log.columns or None,
        "conventions": log.notes or None,
        "finger": log.finger,
        "header": jsonable(log.header),
        "sessions": log.n_sessions,
        "skipped_lines": [{"line": n, "reason": r} for n, r in skipped],
        "event_assignment": jsonable(log.assignment),
    }
    journal = [
        (
            "events assigned",
            {k: summary[k] for k in ("moved", "unread", "undecided", "unassigned_presses")},
        )
    ]
    run_id = write_run(data_dir, f"import-{path.stem}", meta, trials, None, midi, journal, progress)
    return ImportResult(
        run_id,
        "keystroke-log",
        len(trials),
        summary["silent"],
        skipped,
        {"layout": log.layout, "finger": log.finger, **summary, "sessions": log.n_sessions},
        run_dir(data_dir, run_id),
    )


def _tables(log: KeystrokeLog, sha: str) -> tuple[pd.DataFrame, pd.DataFrame]:
    ids = trial_ids(sha, len(log.trials))
    trials = log.trials.copy()
    trials.insert(0, "trial_id", ids)
    trials["attempt"] = 1
    offsets = _session_offsets(log.midi)
    trials["t_start_s"] = math.nan  # the logs never recorded when motion started
    trials["session_offset_s"] = trials["session"].map(offsets).fillna(0.0)
    trials["t_on_log_s"], trials["t_off_log_s"] = trials["t_on_s"], trials["t_off_s"]
    trials["t_on_s"], trials["t_off_s"] = math.nan, math.nan  # relative to motion start: unknown
    index = log.midi["index"].to_numpy(dtype=np.int64)
    id_array = np.asarray(ids, dtype=object)
    midi = pd.DataFrame(
        {
            # an event of a keystroke the log never wrote keeps no trial (null), but is kept
            "trial_id": np.where(
                index >= 0, id_array[np.clip(index, 0, None)] if ids else None, None
            ),
            "t_s": log.midi["t_s"] + log.midi["session"].map(offsets).fillna(0.0),
            "type": log.midi["type"],
            "note": log.midi["note"],
            "velocity": log.midi["velocity"],
        }
    )
    return trials, midi


def _summary(log: KeystrokeLog, trials: pd.DataFrame) -> dict[str, Any]:
    status = trials["status"].value_counts()
    assignment = trials["assignment"].value_counts()
    return {
        "sounded": int(status.get("ok", 0)),
        "silent": int(status.get("silent", 0)),
        "unknown": int(status.get("failed", 0)),
        "moved": int(assignment.get("moved", 0)),
        "unread": int(assignment.get("unread", 0)),
        "undecided": int(assignment.get("undecided", 0)),
        "unassigned_presses": len(log.assignment.get("unassigned_presses", [])),
    }


def _session_offsets(midi: pd.DataFrame) -> dict[int, float]:
    """Start of each session on the run clock: sessions stacked 1 s apart."""
    latest = midi.groupby("session")["t_s"].max() if not midi.empty else pd.Series(dtype=float)
    offsets: dict[int, float] = {}
    running = 0.0
    for session in sorted(int(s) for s in latest.index):
        offsets[session] = running
        running += float(latest[session]) + 1.0
    return offsets
