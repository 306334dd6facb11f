"""`pianobot fit RUN… --model sequence`: the sequence model's grouped-CV table by context length."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from pianobot.analysis.sequence.fit import SequenceFit, fit_sequence_runs
from pianobot.cli.common import Column, command_progress, emit_json, print_table, say, say_written
from pianobot.errors import InputError

SEQUENCE_CV_COLUMNS = (
    Column("model"),
    Column("velocity RMSE (MIDI)", justify="right"),
    Column("velocity MAE (MIDI)", 1, "right"),
    Column("inter-onset RMSE (ms)", justify="right"),
    Column("lead RMSE (ms)", 1, "right"),
    Column("hold RMSE (ms)", 2, "right"),
    Column("silence right (%)", 2, "right"),
)


def parse_context(text: str) -> list[int]:
    """`0,1,2,3` → [0, 1, 2, 3]; InputError naming the bad value otherwise."""
    try:
        ks = sorted({int(part) for part in text.split(",") if part.strip()})
    except ValueError:
        raise InputError(f"expected comma-separated whole numbers such as 0,1,2,3, got {text!r}", "--context") from None
    if not ks or ks[0] < 0 or ks[-1] > 12:
        raise InputError(f"context lengths must lie in [0, 12], got {text!r}", "--context")
    return ks


def fit_sequence_command(runs: Sequence[str], data: Path, kinds: Sequence[str], out_dir: Path, folds: int,
                         context: str, json_out: bool, no_progress: bool) -> None:
    """Run the sequence fit and print (or emit) its table."""
    if "rnn" in kinds:
        from pianobot.analysis.sequence.rnn import require_torch

        require_torch()  # before any data is read: one line on how to install the extra
    per_note = [k for k in kinds if k not in ("sequence", "physics", "rnn")] or ["gp"]
    result = fit_sequence_runs(runs, data, out_dir=out_dir, ks=parse_context(context), per_note=per_note,
                               folds=folds, progress=command_progress(json_out, no_progress), rnn="rnn" in kinds)
    if json_out:
        emit_json(result.to_dict())
        return
    print_sequence_cv(result)


def _number(value: object, fmt: str, scale: float = 1.0) -> str:
    if not isinstance(value, int | float) or value != value:
        return "-"
    return format(float(value) * scale, fmt)


def print_sequence_cv(result: SequenceFit) -> None:
    """The table, a plain sentence on whether context helps, and the file written."""
    rows = [[str(r["model"]) + (" (baseline)" if str(r["model"]).startswith("per-note") else ""),
             _number(r["on_velocity_rmse"], ".2f"), _number(r["on_velocity_mae"], ".2f"),
             _number(r["ioi_rmse_s"], ".0f", 1e3), _number(r["lead_rmse_s"], ".0f", 1e3),
             _number(r["hold_rmse_s"], ".0f", 1e3), _number(r["silent_accuracy"], ".0f", 100.0)]
            for r in result.cv.to_dict(orient="records")]
    folds = int(result.cv["folds"].max())
    print_table(SEQUENCE_CV_COLUMNS, rows, title=f"cross-validation grouped by sequence: {result.n_strokes} strokes "
                                                 f"in {result.n_sequences} sequences, {folds} folds")
    gain = result.context_gain()
    if result.k == 0:
        say("context does not help on these data: the best model is k=0 (the stroke alone)")
    else:
        parts = [f"{name.replace('_rmse', '').replace('_s', '')} RMSE {100 * g:+.1f} %" for name, g in gain.items()]
        say(f"best context: the last {result.k} stroke(s); against k=0: " + ", ".join(parts))
    if result.saved is not None:
        say_written("sequence model", f"{result.saved} (+ {result.saved.with_suffix('.joblib').name})")
