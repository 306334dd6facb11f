"""`pianobot identify`: runs in, identified model file out (with intervals and provenance)."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import pianobot
from pianobot.analysis.greybox.hover import corrected_hover, read_hover
from pianobot.analysis.greybox.layout import gauge_kpa
from pianobot.analysis.greybox.load import load_keystrokes, read_schedule
from pianobot.analysis.greybox.split import split_holdout
from pianobot.analysis.identify.damping import DampingCheck, damping_check
from pianobot.analysis.identify.fit import Coupling, TrajectoryFit, identify_trajectories, rms_x2_m
from pianobot.analysis.identify.readout import ReadoutFit, fit_readout
from pianobot.analysis.identify.static_stiffness import StaticStiffness
from pianobot.executor import ExecutorSettings, open_executor
from pianobot.physics.linear import peak_response
from pianobot.physics.model import KeystrokeModel, save_model
from pianobot.physics.msd import MSDParams
from pianobot.progress import NO_PROGRESS, Progress


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
    notes: tuple[str, ...] = ()  # what the loader decided (a run left out, an assumption)

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


def identify_runs(
    run_ids: Sequence[str], data_dir: Path, *, out: Path | None, coupling: Coupling = "auto",
    bootstrap: int = 20, seed: int = 0, x0_source: str = "auto", vacuum_kpa: float | None = None,
    static: StaticStiffness | None = None, progress: Progress = NO_PROGRESS,
    executor: ExecutorSettings | None = None, schedule: Path | None = None,
) -> IdentifyResult:
    """Identify the model from the runs' trajectories; compare with the published parameters on
    held-out keystrokes (every third per level); write the model file when `out` is given.

    The bootstrap refits run through the executor `executor` asks for (None: in this process),
    sized by how long the held-out fit took; results do not depend on where they ran.
    `schedule`: the commanded presses (`greybox.load.read_schedule`) of runs that do not record
    them (an imported Motive take: without it the fingertip is assumed to start on the key)."""
    loaded = load_keystrokes(run_ids, data_dir, x0_source=x0_source, vacuum_kpa=vacuum_kpa, need_motion=True,
                             schedule=None if schedule is None else read_schedule(schedule))
    batch, hashes, trials = loaded.batch, loaded.hashes, loaded.trials
    notes = list(loaded.notes)
    published = MSDParams()
    train, test = split_holdout(batch)
    started = time.perf_counter()
    with progress.task("identify: held-out fit", total=None):
        held = identify_trajectories(train, prior=published, coupling=coupling)
        # A hover read from the take reads long: corrected by reading the fitted model the same way.
        hover = corrected_hover(batch, KeystrokeModel(msd=held.params)) if read_hover(batch) else None
        if hover is not None:
            batch = hover.batch
            notes.append(hover.note())
            train, test = split_holdout(batch)
            started = time.perf_counter()
            held = identify_trajectories(train, prior=published, coupling=coupling)
    refit_s = (time.perf_counter() - started) / (2 if coupling == "auto" else 1)  # auto fits tied and free
    rms_id = rms_x2_m(test, held.params)
    rms_pub = rms_x2_m(test, published)
    with open_executor(executor or ExecutorSettings(workers=1), work_s=bootstrap * refit_s) as ex:
        with progress.task("identify: fit on every keystroke", total=None):
            fit = identify_trajectories(batch, prior=published, coupling=held.coupling, bootstrap=bootstrap, seed=seed,
                                        progress=progress, mapper=ex.imap)
    model = KeystrokeModel.study().replace(msd=fit.params)
    damping = damping_check(batch, fit.params, seed=seed)
    readout = fit_readout(batch, trials)
    if readout is not None:
        model = model.replace(piano=readout.piano(model.piano))
        if abs(readout.curve_exponent - 1.0) > 0.05:  # the linear readout would misread loudness
            model = model.with_effect("velocity_curve", curve_exponent=min(max(readout.curve_exponent, 0.5), 4.0),
                                      curve_saturation=0.0)
    peaks = {f"{gauge_kpa(p):g}": peak_response(fit.params.at(-abs(p)))[0]
             for p in sorted(set(np.abs(batch.vacuum_kpa).tolist()))}
    path = None
    if out is not None:
        intervals = {e.name: {"value": e.value, "ci95": list(e.ci95), "jacobian": list(e.ci_jacobian),
                              "bootstrap": None if e.ci_bootstrap is None else list(e.ci_bootstrap)}
                     for e in fit.estimates}
        provenance = {
            "clock_offset_s": {"value": batch.clock_offset_s, "se": batch.clock_offset_se_s},
            "method": "output-error least squares (soft-L1, pianobot.analysis.greybox) on mocap trajectories; forward model: the "
                      "measured arm trace drives the fingertip from distance_m above the key, the study's "
                      "coupling from touch, each keystroke fitted until the fingertip lifts off",
            "runs": list(hashes), "data_sha256": hashes, "pianobot_version": pianobot.__version__,
            "fixed": fit.fixed, "coupling": fit.coupling, "on_bounds": list(fit.on_bounds), "bootstrap": bootstrap, "seed": seed,
            "holdout_rms_x2_m": {"identified": rms_id, "published": rms_pub},
            "damping_check": None if damping is None else damping.to_dict(),
            "readout": None if readout is None else readout.to_dict(),
        }
        if static is not None:
            provenance["static_stiffness"] = static.to_dict()
        path = save_model(model, out, intervals=intervals, provenance=provenance)
    return IdentifyResult(fit, model, rms_id, rms_pub, peaks, static, path, damping, readout, batch.clock_offset_s,
                          tuple(notes))
