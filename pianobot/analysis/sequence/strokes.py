"""Trials as sequences of strokes: order, own controls, outcomes and the note-on clock.

A stroke's outcome depends on the strokes before it (where the finger comes from, how long the
previous key was held, a finger state that persists). The sequence model needs the trials in
the order they were played, grouped into sequences:

- trials with `sequence_id` / `sequence_order` (the study's sequential log, sequence-mode
  sweeps) form one sequence per (run, sequence id);
- trials without them (a play run, a sweep) were still played one after another: each run is
  cut into consecutive stretches of `STRETCH_STROKES` strokes, in `index` order, so that
  cross-validation can hold whole stretches out (a play run's warm-up and song apart).

Failed trials are dropped before ordering: the previous stroke is the previous one that ran.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.analysis.learn.predictors import INPUT_COLUMNS
from pianobot.errors import InputError

FloatArray = npt.NDArray[np.float64]

#: Controls a stroke may carry beyond the per-note inputs (imported logs record the sideways
#: move and the upward acceleration).
EXTRA_CONTROLS: tuple[str, ...] = ("up_acceleration_mps2", "move_velocity_mps", "move_acceleration_mps2")
CONTROL_COLUMNS: tuple[str, ...] = ("note", *INPUT_COLUMNS, *EXTRA_CONTROLS)
#: Strokes per stretch when a run carries no sequence ids (the study's sequences had 12).
STRETCH_STROKES = 12
#: Regression targets: on-velocity and MIDI hold of sounded strokes, the lead from motion start
#: to note-on (where the motion start is known), and the inter-onset interval: previous
#: stroke's note-on → this note-on (known wherever both sounded, also in old logs).
TARGETS: tuple[str, ...] = ("on_velocity", "midi_hold_s", "lead_s", "ioi_s")


@dataclass(frozen=True)
class StrokeSequences:
    """Executed strokes in play order: one row per stroke, grouped into sequences.

    `frame` columns: `sequence` (int, one per (run, sequence)), `order` (position in it, from
    0), the controls `controls` (those that vary), `silent` (bool) and every target of
    `TARGETS` (NaN where unknown).
    """

    frame: pd.DataFrame
    controls: tuple[str, ...]

    @property
    def n(self) -> int:
        return len(self.frame)

    @property
    def groups(self) -> npt.NDArray[np.int64]:
        return self.frame["sequence"].to_numpy(np.int64)

    @property
    def n_sequences(self) -> int:
        return int(self.frame["sequence"].nunique())


def stroke_sequences(trials: pd.DataFrame, controls: tuple[str, ...] | None = None) -> StrokeSequences:
    """Order executed trials into sequences and compute the targets.

    `controls`: the control columns to use (a fitted model's); default: those that vary.

    Raises:
        InputError: no executed trial, or no sounded stroke.
    """
    if trials is None or trials.empty:
        raise InputError("the run has no trials", "fit --model sequence")
    frame = trials
    if "status" in frame:
        frame = frame[frame["status"].isin(["ok", "silent"])]
    frame = frame.dropna(subset=["down_velocity_mps"])
    if frame.empty:
        raise InputError("the run has no executed trials (all failed or missing parameters)", "fit --model sequence")
    frame = _ordered(frame)
    out = pd.DataFrame({"sequence": frame["_sequence"].to_numpy(np.int64),
                        "order": frame["_order"].to_numpy(np.int64)})
    for name in CONTROL_COLUMNS:
        out[name] = _column(frame, name)
    on = _column(frame, "on_velocity")
    silent = np.isnan(on) | (frame["status"].eq("silent").to_numpy() if "status" in frame else False)
    out["silent"] = silent
    out["on_velocity"] = np.where(silent, np.nan, on)
    out["midi_hold_s"] = np.where(silent, np.nan, _column(frame, "midi_hold_s"))
    out["lead_s"] = np.where(silent, np.nan, _column(frame, "t_on_s"))
    onset = np.where(silent, np.nan, _onset_clock_s(frame))
    previous = pd.Series(onset).groupby(out["sequence"].to_numpy()).shift(1).to_numpy(float)
    out["ioi_s"] = onset - previous
    if out["silent"].all():
        raise InputError("every keystroke is silent: nothing to learn on-velocity from", "fit --model sequence")
    if controls is None:
        controls = tuple(c for c in CONTROL_COLUMNS if out[c].notna().all() and out[c].nunique() > 1)
        if "down_velocity_mps" not in controls:
            controls = ("down_velocity_mps", *controls)
    return StrokeSequences(out.reset_index(drop=True), tuple(controls))


def _column(frame: pd.DataFrame, name: str) -> FloatArray:
    if name not in frame:
        if name == "up_velocity_mps":
            return frame["down_velocity_mps"].to_numpy(float)
        return np.full(len(frame), np.nan)
    return pd.to_numeric(frame[name], errors="coerce").to_numpy(float)


def _ordered(frame: pd.DataFrame) -> pd.DataFrame:
    """Sort into play order and number the sequences 0, 1, … (`_sequence`, `_order`)."""
    frame = frame.copy()
    run = frame["run_id"].astype(str) if "run_id" in frame else pd.Series("", index=frame.index)
    index = frame["index"].to_numpy(np.int64) if "index" in frame else np.arange(len(frame))
    # Runs without sequence ids (a play run, a sweep; or mixed with runs that have them):
    # consecutive stretches in run order, a play run's warm-up and song cut apart (no stretch
    # spans the pause between them).
    phase = frame["phase"].astype(str) if "phase" in frame else pd.Series("", index=frame.index)
    rank = pd.Series(index, index=frame.index).groupby([run, phase]).rank(method="first").to_numpy(int) - 1
    seq = np.array([f"{p}:{r // STRETCH_STROKES:09d}" for p, r in zip(phase, rank, strict=True)], dtype=object)
    order = rank % STRETCH_STROKES
    if "sequence_id" in frame and "sequence_order" in frame:
        has = (frame["sequence_id"].notna() & frame["sequence_order"].notna()).to_numpy()
        ids = pd.to_numeric(frame["sequence_id"], errors="coerce").to_numpy(float)
        seq[has] = [f"id:{int(v):09d}" for v in ids[has]]
        order = np.where(has, pd.to_numeric(frame["sequence_order"], errors="coerce").fillna(0).to_numpy(float),
                         order).astype(np.int64)
    frame["_run"], frame["_seq"], frame["_order"], frame["_index"] = run.to_numpy(), seq, order, index
    frame = frame.sort_values(["_run", "_seq", "_order", "_index"], kind="stable")
    keys = list(zip(frame["_run"], frame["_seq"], strict=True))
    frame["_sequence"] = pd.factorize(pd.Series(keys, index=frame.index))[0]
    return frame


def _onset_clock_s(frame: pd.DataFrame) -> FloatArray:
    """Each stroke's note-on on one clock per run: the run clock (motion start + lead), or an
    imported log's MIDI clock."""
    start = _column(frame, "t_start_s")
    lead = _column(frame, "t_on_s")
    onset = start + lead
    log = _column(frame, "t_on_log_s")
    return np.where(np.isfinite(onset), onset, log)
