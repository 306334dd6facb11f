"""Turn stored runs into the measured keystrokes discovery compares against.

Positions come from the mocap source only (the arm log is the command's echo and sim-truth is
not a measurement); every trace is referenced to its own rest level, because a mocap marker sits
at an arbitrary height above the surface it tracks. MIDI outcomes come from the trials table.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from pianobot.analysis.discover.data import Keystroke
from pianobot.errors import InputError
from pianobot.physics.model import KeystrokeModel, load_model
from pianobot.physics.trajectory import Press
from pianobot.store import Run, load_run

_REST_SAMPLES = 6


def _rest_referenced(t_s: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Values relative to their level before motion start (t_s ≤ 0), when such samples exist.

    The store's convention already puts the start pose at 0; an importer that keeps a marker's
    absolute height still records samples before the motion, which give the rest level.
    """
    rest = values[(t_s <= 0.0) & np.isfinite(values)]
    if rest.size == 0:
        return values
    return values - float(np.median(rest[-_REST_SAMPLES:]))


def _float(row: pd.Series, name: str, default: float = float("nan")) -> float:
    value = row.get(name, default)
    try:
        out = float(value)
    except (TypeError, ValueError):
        return default
    return out if math.isfinite(out) else default


# UR moveL's default tool acceleration: assumed when a run (an imported mocap take) does not
# record the acceleration it was played with.
DEFAULT_ACCELERATION_MPS2 = 1.2


def _press(row: pd.Series, notes: set[str]) -> Press | None:
    """The commanded press of a trial; missing parameters are derived and noted, or None."""
    down = _float(row, "down_velocity_mps")
    if not math.isfinite(down) or down <= 0:
        down = _float(row, "arm_speed_mps")  # an imported take's arm speed estimate
        notes.add("down velocity taken from the measured arm speed")
    if not math.isfinite(down) or down <= 0:
        return None
    distance = _float(row, "distance_m")
    if not math.isfinite(distance):
        distance = 0.0
        notes.add("distance 0 assumed (finger starts on the key)")
    depth = _float(row, "depth_m")
    if not math.isfinite(depth):
        depth = _float(row, "arm_travel_m") - distance  # measured arm travel = distance + depth
        notes.add("depth taken from the measured arm travel")
    if not math.isfinite(depth) or depth <= 0:
        return None
    accel = _float(row, "acceleration_mps2")
    if not math.isfinite(accel) or accel <= 0:
        accel = DEFAULT_ACCELERATION_MPS2
        notes.add(f"acceleration {DEFAULT_ACCELERATION_MPS2} m/s² assumed (UR moveL default)")
    up = _float(row, "up_velocity_mps")
    hold = _float(row, "hold_s")
    if not math.isfinite(hold):
        # An imported take times its strokes: with equal down and up moves, the hold is what
        # the stroke lasts beyond twice the time to the bottom.
        start, bottom, end = (_float(row, c) for c in ("t_start_s", "t_bottom_s", "t_end_s"))
        hold = max((end - start) - 2.0 * (bottom - start), 0.0)
        if math.isfinite(hold):
            notes.add("hold derived from the take's stroke timing (equal down and up moves)")
        else:
            hold = 0.0
    return Press(
        distance_m=distance,
        depth_m=depth,
        down_velocity_mps=down,
        up_velocity_mps=up if math.isfinite(up) and up > 0 else down,
        acceleration_mps2=accel,
        hold_s=hold,
    )


def keystrokes_from_run(
    run: Run, vacuum_kpa: float | None = None, notes: set[str] | None = None
) -> list[Keystroke]:
    """Every ok or silent trial of a run as a measured keystroke.

    Args:
        vacuum_kpa: the vacuum of trials that do not record one (an imported mocap take).
        notes: collects the assumptions made for parameters the run does not record.

    Raises:
        InputError: when the run has no usable trial (no press parameters).
    """
    notes = set() if notes is None else notes
    trials = run.trials
    if trials.empty:
        raise InputError("the run has no trials", run.run_id)
    trials = trials[trials["status"].isin(["ok", "silent"])]
    samples = run.samples
    mocap = samples[samples["source"] == "mocap"] if not samples.empty else samples
    by_trial = dict(tuple(mocap.groupby("trial_id", sort=False))) if not mocap.empty else {}
    has_midi = bool(not run.midi.empty or trials["on_velocity"].notna().any())
    out: list[Keystroke] = []
    for _, row in trials.iterrows():
        trial_id = str(row["trial_id"])
        press = _press(row, notes)
        if press is None:
            continue
        vacuum = _float(row, "vacuum_kpa")
        if not math.isfinite(vacuum):
            if vacuum_kpa is None:
                raise InputError(
                    "trials do not record their vacuum level; give it with --vacuum-kpa",
                    run.run_id,
                )
            vacuum = vacuum_kpa
        group = by_trial.get(trial_id)
        if group is not None and len(group) > 8:
            group = group.sort_values("t_s")
            t = group["t_s"].to_numpy(np.float64)
            x = np.vstack(
                [
                    _rest_referenced(t, group[c].to_numpy(np.float64))
                    for c in ("x0_m", "x1_m", "x2_m")
                ]
            )
        else:
            t, x = np.empty(0), np.empty((3, 0))
        sounded = (
            None
            if not has_midi
            else bool(row["status"] == "ok" and np.isfinite(_float(row, "on_velocity")))
        )
        out.append(
            Keystroke(
                key_id=f"{run.run_id}/{trial_id}",
                press=press,
                vacuum_kpa=vacuum,
                t_s=t,
                x_m=x,
                on_velocity=_float(row, "on_velocity"),
                t_on_s=_float(row, "t_on_s"),
                t_off_s=_float(row, "t_off_s"),
                sounded=sounded,
            )
        )
    if not out:
        raise InputError("the run has no ok or silent trial with press parameters", run.run_id)
    return out


def load_keystrokes(
    run_ids: Sequence[str],
    data_dir: Path,
    vacuum_kpa: float | None = None,
    notes: set[str] | None = None,
) -> list[Keystroke]:
    """Keystrokes of several runs, in run order (see `keystrokes_from_run`).

    Raises:
        InputError: no run id given, an unknown run, or a run without usable trials.
    """
    if not run_ids:
        raise InputError("give at least one run id", "RUN_ID")
    keystrokes: list[Keystroke] = []
    for run_id in run_ids:
        keystrokes.extend(keystrokes_from_run(load_run(run_id, data_dir), vacuum_kpa, notes))
    if not any(k.has_motion for k in keystrokes) and not any(
        k.sounded is not None for k in keystrokes
    ):
        raise InputError("the runs have neither mocap samples nor MIDI outcomes", ",".join(run_ids))
    return keystrokes


def resolve_model(spec: str) -> KeystrokeModel:
    """`study` (the study's linear model with its constant-speed ramp) or a model file path.

    Raises:
        InputError: the file is missing or not a model file.
    """
    if spec == "study":
        return KeystrokeModel.study()
    return load_model(Path(spec))
