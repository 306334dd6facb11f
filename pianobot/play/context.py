"""Planning each note with the context the song gives it: a sequence model's correction.

`pianobot play song.mid --model sequence.json` (a file of `pianobot fit RUN… --model sequence`)
plans as the per-note planner does — the warm-up fits this piano's loudness, lead and hold maps,
and those stay the plan's absolute scale — and then asks the sequence model what the notes
before each note change in it: its on-velocity and its lead (motion start → note-on), with the
strokes the plan gives its predecessors (`SequenceModel.planned_effect`), against the context the
per-note maps were learned in (the warm-up's strokes, in the order played: after a warm-up that
moved from key to key, a moved-to note is not corrected, a repeated one is). The planner aims each
note at its target minus the context's loudness effect, and starts its motion earlier or later
by the context's lead effect (never before the arm is free); two passes, since a changed stroke
changes the context of the next.

A sequence model is used for a target only where its own grouped cross-validation (which travels
with the file) showed both that context cuts the error against the same model without context by
at least `MIN_GAIN`, and that with context it predicts held-out sequences better than the per-note
model did on the same folds: a context that did not predict better would only add the model's
noise to a plan (on the simulated rig, trees predict the lead to ~40 ms where the per-note GP
does to ~4 ms, whatever the context adds). A model whose context helps nowhere plans exactly as
the per-note planner, and `play` says so.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from pianobot.analysis.sequence.files import SEQUENCE_SCHEMA, load_sequence_model
from pianobot.analysis.sequence.model import SequenceModel
from pianobot.spec.parameters import PARAMETER_NAMES

FloatArray = npt.NDArray[np.float64]

#: Least relative cut of the cross-validated error (chosen k against k = 0) for a target's
#: context to be used.
MIN_GAIN = 0.02
#: The plan's columns under the names the sequence model's controls carry (the plan calls the
#: note its pitch).
CONTROLS = {name: "pitch" if name == "note" else name for name in PARAMETER_NAMES}
NAMES = {"on_velocity": "loudness", "lead_s": "lead"}
#: Targets the planner corrects, with the cross-validation column that decides.
USED: dict[str, str] = {"on_velocity": "on_velocity_rmse", "lead_s": "lead_rmse_s"}


def is_sequence_file(path: Path) -> bool:
    """Whether `path` is a sequence model's JSON sidecar (by its schema, whatever its name)."""
    try:
        payload = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return False
    return isinstance(payload, dict) and payload.get("schema") == SEQUENCE_SCHEMA


def _finite(value: Any) -> bool:
    return isinstance(value, int | float) and bool(np.isfinite(value))


def context_gains(cv: list[dict[str, Any]], k: int) -> dict[str, float]:
    """Relative change of each used target's CV error, k against k = 0 (negative: context helps)."""
    rows = {r.get("model"): r for r in cv}
    base, best = rows.get("sequence k=0"), rows.get(f"sequence k={k}")
    out: dict[str, float] = {}
    if base is None or best is None:
        return out
    for target, column in USED.items():
        b, v = base.get(column), best.get(column)
        if isinstance(b, int | float) and isinstance(v, int | float) and _finite(b) and _finite(v) and b > 0:
            out[target] = float(v) / float(b) - 1.0
    return out


def beats_per_note(cv: list[dict[str, Any]], k: int) -> dict[str, bool]:
    """Per used target: whether the sequence model with k predicted held-out sequences better
    than every per-note model in the same CV (True when there was none to compare with)."""
    best = next((r for r in cv if r.get("model") == f"sequence k={k}"), None)
    per_note = [r for r in cv if str(r.get("model", "")).startswith("per-note")]
    out: dict[str, bool] = {}
    for target, column in USED.items():
        v = None if best is None else best.get(column)
        rivals = [float(r[column]) for r in per_note if _finite(r.get(column))]
        out[target] = isinstance(v, int | float) and bool(np.isfinite(v)) and all(v < rival for rival in rivals)
    return out


@dataclass(frozen=True)
class SongContext:
    """A sequence model and the targets whose context the planner uses."""

    model: SequenceModel
    source: str
    gains: dict[str, float]  # CV error change per target, chosen k against k = 0
    better: dict[str, bool] = field(default_factory=dict)  # beats the per-note model (CV), per target
    #: Strokes in the order played from which the plan's per-note model was learned (a play's
    #: warm-up): the context the effects are measured against. None: the model's training contexts.
    reference: pd.DataFrame | None = None

    @classmethod
    def load(cls, path: Path) -> SongContext:
        """Open a sequence model file (InputError when missing, changed or of another schema)."""
        payload = json.loads(Path(path).read_text(encoding="utf-8"))
        model = load_sequence_model(Path(path), payload)
        cv = list(payload.get("cv") or [])
        return cls(model, str(path), context_gains(cv, model.k), beats_per_note(cv, model.k))

    def calibrated_on(self, strokes: pd.DataFrame) -> SongContext:
        """The same context, its effects measured against the context of `strokes` (the warm-up
        the per-note model was just fitted on: what that model predicts already includes it)."""
        played = strokes[strokes["status"].isin(["ok", "silent"])] if "status" in strokes else strokes
        return dataclasses.replace(self, reference=played.reset_index(drop=True))

    @property
    def used(self) -> tuple[str, ...]:
        """Targets corrected: context cut their held-out error by at least `MIN_GAIN`, and the
        model with context beat the per-note model on them."""
        if self.model.k == 0:
            return ()
        return tuple(t for t in USED if self.gains.get(t, 0.0) <= -MIN_GAIN and self.better.get(t, True))

    def describe(self) -> str:
        """One line for the user: what the context corrects and why (or why nothing)."""
        k = self.model.k
        measured = ", ".join(f"{t.replace('_s', '').replace('_', '-')} {100 * g:+.1f} %" for t, g in self.gains.items())
        worse = [t.replace("_s", "").replace("_", "-") for t, ok in self.better.items() if not ok]
        if not self.used:
            why = "the model uses no context (k=0)" if k == 0 else (
                f"with the last {k} stroke(s) its cross-validated error did not fall by {100 * MIN_GAIN:.0f} % "
                f"against no context ({measured or 'not measured'})"
                + (f" or stayed above the per-note model's ({', '.join(worse)})" if worse else ""))
            return f"sequence model {self.source}: {why}; every note is planned alone"
        return (f"sequence model {self.source}: each note's {' and '.join(NAMES[u] for u in self.used)} "
                f"planned with the last {k} note(s) as context (cross-validated error against no context: {measured})")

    def effects(self, plan: pd.DataFrame) -> tuple[FloatArray, FloatArray]:
        """Per plan row, the context's change of on-velocity and of lead (0 for skipped notes
        and for targets not used)."""
        n = len(plan)
        dv, dlead = np.zeros(n), np.zeros(n)
        played = (plan["status"] == "play").to_numpy()
        if not self.used or not played.any():
            return dv, dlead
        strokes = pd.DataFrame({name: plan.loc[played, column].to_numpy(float)
                                for name, column in CONTROLS.items() if column in plan})
        effect = self.model.planned_effect(strokes, self.reference)
        if "on_velocity" in self.used:
            dv[played] = np.nan_to_num(effect["on_velocity"].to_numpy(float))
        if "lead_s" in self.used:
            dlead[played] = np.nan_to_num(effect["lead_s"].to_numpy(float))
        return dv, dlead
