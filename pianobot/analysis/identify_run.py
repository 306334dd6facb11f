"""`pianobot identify`: runs in, identified model file out (with intervals and provenance)."""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

import pianobot
from pianobot.analysis.damping import DampingCheck, damping_check
from pianobot.analysis.identify import TrajectoryFit, identify_trajectories, rms_x2_m, split_holdout
from pianobot.analysis.keystroke_batch import KeystrokeBatch, keystroke_batch
from pianobot.analysis.readout_fit import ReadoutFit, fit_readout
from pianobot.analysis.static_stiffness import StaticStiffness
from pianobot.errors import InputError
from pianobot.physics.linear import peak_response
from pianobot.physics.model import KeystrokeModel, save_model
from pianobot.physics.msd import MSDParams
from pianobot.store import load_run


@dataclass(frozen=True)
class IdentifyResult:
    """What `identify` found: the fit, held-out comparison and the written model file."""

    fit: TrajectoryFit
    model: KeystrokeModel
    holdout_rms_identified_m: float
    holdout_rms_published_m: float
    peak_hz: dict[str, float]
    static: StaticStiffness | None
    model_path: Path | None
    damping: DampingCheck | None = None
    readout: ReadoutFit | None = None
    clock_offset_s: float = 0.0  # mocap clock behind the arm log's (the arm log was shifted by it)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "parameters": {e.name: e.row() for e in self.fit.estimates},
            "coupling": self.fit.coupling,
            "fixed": self.fit.fixed,
            "clock_offset_s": self.clock_offset_s,
            "rms_m": self.fit.rms_m,
            "n_keystrokes": self.fit.n_keystrokes,
            "holdout_rms_x2_identified_m": self.holdout_rms_identified_m,
            "holdout_rms_x2_published_m": self.holdout_rms_published_m,
            "x2_x0_peak_hz": self.peak_hz,
            "model_file": None if self.model_path is None else str(self.model_path),
            "damping_check": None if self.damping is None else self.damping.to_dict(),
            "readout": None if self.readout is None else self.readout.to_dict(),
        }
        if self.static is not None:
            out["static_stiffness"] = self.static.to_dict()
        return out


def _file_hash(path: Path) -> str:
    digest = hashlib.sha256()
    for name in ("trials.parquet", "samples.parquet"):
        file = path / name
        if file.is_file():
            digest.update(file.read_bytes())
    return digest.hexdigest()


def load_batch(run_ids: Sequence[str], data_dir: Path, *, x0_source: str = "auto",
               vacuum_kpa: float | None = None) -> tuple[KeystrokeBatch, dict[str, str]]:
    """Keystroke batch over several runs (trial ids prefixed by run), and each run's data hash."""
    batch, hashes, _ = load_batch_trials(run_ids, data_dir, x0_source=x0_source, vacuum_kpa=vacuum_kpa)
    return batch, hashes


def load_batch_trials(run_ids: Sequence[str], data_dir: Path, *, x0_source: str = "auto",
                      vacuum_kpa: float | None = None) -> tuple[KeystrokeBatch, dict[str, str], pd.DataFrame]:
    """`load_batch` plus the runs' trials, with the same prefixed trial ids."""
    samples, trials, hashes = [], [], {}
    for run_id in run_ids:
        run = load_run(run_id, data_dir)
        t, s = run.trials, run.samples
        if t.empty:
            raise InputError("the run has no trials", run.run_id)
        if vacuum_kpa is not None:
            t = t.assign(vacuum_kpa=vacuum_kpa)
        if t["vacuum_kpa"].isna().all():
            raise InputError("the run records no vacuum level; give --vacuum-kpa", run.run_id)
        prefix = f"{run.run_id}/"
        trials.append(t.assign(trial_id=prefix + t["trial_id"].astype(str)))
        samples.append(s.assign(trial_id=prefix + s["trial_id"].astype(str)))
        hashes[run.run_id] = _file_hash(run.path)
    all_trials = pd.concat(trials, ignore_index=True)
    batch = keystroke_batch(pd.concat(samples, ignore_index=True), all_trials, x0_source=x0_source)
    return batch, hashes, all_trials


def identify_runs(
    run_ids: Sequence[str], data_dir: Path, *, out: Path | None, coupling: str = "auto",
    bootstrap: int = 20, seed: int = 0, x0_source: str = "auto", vacuum_kpa: float | None = None,
    static: StaticStiffness | None = None,
) -> IdentifyResult:
    """Identify the model from the runs' trajectories; compare with the published parameters on
    held-out keystrokes (every third per level); write the model file when `out` is given."""
    batch, hashes, trials = load_batch_trials(run_ids, data_dir, x0_source=x0_source, vacuum_kpa=vacuum_kpa)
    published = MSDParams()
    train, test = split_holdout(batch)
    held = identify_trajectories(train, prior=published, coupling=coupling)  # type: ignore[arg-type]
    rms_id = rms_x2_m(test, held.params)
    rms_pub = rms_x2_m(test, published)
    fit = identify_trajectories(batch, prior=published, coupling=held.coupling, bootstrap=bootstrap, seed=seed)
    model = KeystrokeModel.study().replace(msd=fit.params)
    damping = damping_check(batch, fit.params, seed=seed)
    readout = fit_readout(batch, trials)
    if readout is not None:
        model = model.replace(piano=readout.piano(model.piano))
        if abs(readout.curve_exponent - 1.0) > 0.05:  # the linear readout would misread loudness
            model = model.with_effect("velocity_curve", curve_exponent=min(max(readout.curve_exponent, 0.5), 4.0),
                                      curve_saturation=0.0)
    peaks = {f"{-abs(p):g}": peak_response(fit.params.at(-abs(p)))[0]
             for p in sorted(set(np.abs(batch.vacuum_kpa).tolist()))}
    path = None
    if out is not None:
        intervals = {e.name: {"value": e.value, "ci95": list(e.ci95), "jacobian": list(e.ci_jacobian),
                              "bootstrap": None if e.ci_bootstrap is None else list(e.ci_bootstrap)}
                     for e in fit.estimates}
        provenance = {
            "clock_offset_s": {"value": batch.clock_offset_s, "se": batch.clock_offset_se_s},
            "method": "output-error least squares (soft-L1) on mocap trajectories; forward model: the "
                      "measured arm trace drives the fingertip from distance_m above the key, the study's "
                      "coupling from touch, each keystroke fitted until the fingertip lifts off",
            "runs": list(hashes), "data_sha256": hashes, "pianobot_version": pianobot.__version__,
            "fixed": fit.fixed, "coupling": fit.coupling, "bootstrap": bootstrap, "seed": seed,
            "holdout_rms_x2_m": {"identified": rms_id, "published": rms_pub},
            "damping_check": None if damping is None else damping.to_dict(),
            "readout": None if readout is None else readout.to_dict(),
        }
        if static is not None:
            provenance["static_stiffness"] = static.to_dict()
        path = save_model(model, out, intervals=intervals, provenance=provenance)
    return IdentifyResult(fit, model, rms_id, rms_pub, peaks, static, path, damping, readout, batch.clock_offset_s)
