"""Sequence-mode collection, as the study's script did it: random notes in order, with every
stroke's parameters drawn uniformly at random, played one after another.

`random_sequences` is the plan (pure, seeded): `n_sequences` sequences of `length` strokes, the
note of each stroke drawn from `notes`, each parameter of `ranges` drawn uniformly per stroke,
`fixed` parameters held. `play_on_world` plays a plan on a simulated `World` and returns a
trials table (the columns `pianobot fit --model sequence` reads: `sequence_id`,
`sequence_order`, `note`, the controls, `status`, `on_velocity`, `t_on_s`, `midi_hold_s`,
`t_start_s`).

The default simulated world has no state that carries from one keystroke to the next: every
keystroke starts from rest, and its finger-stiffness drift (`stiffness_drift`) is drawn per
block, which the sim rig makes one per vacuum level. `play_on_world(…, stiffness_per_sequence=
True)` makes each sequence its own drift block — the finger is re-stiffened between
sequences, so the strokes of one sequence share a finger state that differs from the next
sequence's. That is a world where context matters: a stroke's predecessors reveal the state.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from pianobot.physics.trajectory import press_duration_s
from pianobot.physics.world import World
from pianobot.plan.trial import press_from
from pianobot.spec.parameters import PARAMETERS, PRESS_PARAMETERS, missing_value

#: Pause between one stroke's end and the next stroke's start (the sideways move), seconds.
MOVE_S = 0.3


def random_sequences(n_sequences: int, length: int, *, notes: Sequence[int],
                     ranges: Mapping[str, tuple[float, float]], fixed: Mapping[str, float],
                     seed: int = 0) -> pd.DataFrame:
    """The plan: one row per stroke (`sequence_id`, `sequence_order`, `note`, parameters).

    Raises:
        ValueError: no sequences, no notes, an empty range, or a press field left undefined.
    """
    if n_sequences < 1 or length < 1:
        raise ValueError(f"need at least one sequence of one stroke, got {n_sequences} x {length}")
    if not notes:
        raise ValueError("need at least one note to draw from")
    for name, (lo, hi) in ranges.items():
        if not hi >= lo:
            raise ValueError(f"range of {name} is empty: [{lo}, {hi}]")
    missing = [f for f in (*PRESS_PARAMETERS, "vacuum_kpa") if f not in ranges and f not in fixed
               and PARAMETERS[f].follows is None]
    if missing:
        raise ValueError(f"parameters neither drawn nor fixed: {', '.join(missing)}")
    rng = np.random.default_rng(seed)
    n = n_sequences * length
    frame = pd.DataFrame({
        "sequence_id": np.repeat(np.arange(n_sequences), length),
        "sequence_order": np.tile(np.arange(length), n_sequences),
        "note": rng.choice(np.asarray(notes, dtype=np.int64), size=n),
    })
    for name, (lo, hi) in ranges.items():
        frame[name] = rng.uniform(lo, hi, n)
    for name, value in fixed.items():
        frame[name] = float(value)
    for name in PRESS_PARAMETERS:  # the up velocity follows the down velocity (the parameter table)
        if name not in frame:
            frame[name] = missing_value(name, {c: frame[c] for c in frame.columns})
    frame["index"] = np.arange(n)
    return frame


def play_on_world(world: World, plan: pd.DataFrame, *, stiffness_per_sequence: bool = False,
                  run_id: str = "sim-sequences") -> pd.DataFrame:
    """Play `plan` (`random_sequences`, or a sequence-mode spec's `plan_frame`) on `world`; the
    trials table of what was heard."""
    presses = [press_from(row) for row in plan[list(PRESS_PARAMETERS)].to_dict("records")]
    vacuum = plan["vacuum_kpa"].to_numpy(float)
    blocks: list[str | None] = ([f"sequence-{int(s)}" for s in plan["sequence_id"]] if stiffness_per_sequence
                                else [None] * len(plan))
    world.prefetch(presses, vacuum, blocks)
    rows = []
    t_s = 0.0
    for i, (press, (_, row)) in enumerate(zip(presses, plan.iterrows(), strict=True)):
        stroke = world.keystroke(press, float(vacuum[i]), note=int(row["note"]), t0_s=t_s,
                                 key=f"{run_id}-{i}", block=blocks[i])
        ons = [e for e in stroke.midi if e.type == "note_on"]
        offs = [e for e in stroke.midi if e.type == "note_off" and ons and e.t_s >= ons[0].t_s]
        rows.append({
            **row.to_dict(), "run_id": run_id, "trial_id": f"{run_id}-{i:05d}",
            "status": "ok" if ons else "silent", "t_start_s": t_s,
            "on_velocity": float(ons[0].velocity) if ons else np.nan,
            "t_on_s": ons[0].t_s - t_s if ons else np.nan,
            "midi_hold_s": offs[0].t_s - ons[0].t_s if offs else np.nan,
        })
        t_s += max(stroke.duration_s, press_duration_s(press)) + MOVE_S
    return pd.DataFrame(rows)
