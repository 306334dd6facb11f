"""`pianobot discover RUN…`: load the runs, discover, write the updated model file."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pianobot.analysis.discover.loop import Settings, discover
from pianobot.analysis.discover.result import DiscoveryResult
from pianobot.analysis.greybox.load import load_keystrokes, read_schedule
from pianobot.analysis.greybox.pieces import Mapper
from pianobot.errors import InputError
from pianobot.executor import ExecutorSettings, open_executor
from pianobot.physics.model import KeystrokeModel, load_model, save_model
from pianobot.progress import NO_PROGRESS, Progress

#: Fewer keystrokes than this cannot be split into a training and a held-out part worth judging.
MIN_KEYSTROKES = 6
#: Serial CPU per keystroke of a discovery (measured in benchmarks/bench_discover.py: 4-60 s per
#: 24-keystroke take, about 45 s per 135-keystroke log): whether a local cluster pays for itself.
WORK_PER_KEYSTROKE_S = 0.5
#: The vacuum assumed for a run that records none (a Motive take): the middle of the study's
#: 0 to -80 kPa. The base fit finds the finger's own stiffness; the level only sets where it starts.
ASSUMED_VACUUM_KPA = -40.0


def resolve_model(spec: str) -> KeystrokeModel:
    """`study` (the study's linear model with its constant-speed ramp) or a model file path.

    Raises:
        InputError: the file is missing or not a model file.
    """
    if spec == "study":
        return KeystrokeModel.study()
    return load_model(Path(spec))


def discover_runs(run_ids: Sequence[str], data_dir: Path, model: str = "study", *, seed: int = 0,
                  model_out: Path | None = None, vacuum_kpa: float | None = None, schedule: Path | None = None,
                  progress: Progress = NO_PROGRESS, mapper: Mapper | None = None,
                  executor: ExecutorSettings | None = None) -> DiscoveryResult:
    """Load runs, run discovery from `model` ("study" or a model file), save the final model.

    `schedule` is a CSV of the commanded presses (`greybox.load.SCHEDULE_COLUMNS`) for runs that
    do not record them, e.g. an imported Motive take and the lab script's log of what it sent.
    Candidate fits run through `mapper` when given, else through the executor `executor` asks
    for (`pianobot.executor`; None: in this process); results do not depend on where they ran.

    Raises:
        InputError: unknown runs, runs without mocap or MIDI, too few keystrokes, a bad model file.
    """
    start = resolve_model(model)
    loaded = load_keystrokes(run_ids, data_dir, vacuum_kpa=vacuum_kpa, assumed_vacuum_kpa=ASSUMED_VACUUM_KPA,
                             schedule=None if schedule is None else read_schedule(schedule))
    batch = loaded.batch
    if batch.n < MIN_KEYSTROKES:
        raise InputError(f"discovery needs at least {MIN_KEYSTROKES} keystrokes, got {batch.n}", "RUN_ID")
    if not batch.has_motion and not batch.commanded:
        lacking = [f"{name} ({int(np.sum(~np.isfinite(values)))} of {batch.n} keystrokes)"
                   for name, values in (("speed", batch.down_velocity_mps), ("depth", batch.depth_m))
                   if not np.all(np.isfinite(values))]
        raise InputError(f"the runs have MIDI but no commanded {' and '.join(lacking)} to drive the model with",
                         ",".join(run_ids))
    notes = list(loaded.notes)
    if not batch.has_motion and "acceleration not recorded" in notes:
        notes[notes.index("acceleration not recorded")] = "acceleration not recorded: fitted as a drive parameter"
    elif batch.has_motion:
        notes = [n for n in notes if n != "acceleration not recorded"]  # the measured arm drives the model
    if mapper is not None or executor is None:
        result = discover(batch, start, Settings(seed=seed), notes=notes, progress=progress, mapper=mapper)
    else:
        with open_executor(executor, work_s=WORK_PER_KEYSTROKE_S * batch.n) as ex:
            result = discover(batch, start, Settings(seed=seed), notes=notes, progress=progress, mapper=ex.imap)
    if model_out is not None:
        intervals = {name: list(ci) for v in result.accepted for name, ci in v.intervals.items()}
        save_model(result.final_model, model_out, intervals=intervals, provenance={
            "command": "discover", "runs": list(run_ids), "data_sha256": loaded.hashes, "start_model": model,
            "accepted_effects": [v.label for v in result.accepted],
            "measured_effects": list(result.measured_effects), "verdict": result.verdict, "seed": seed})
    return result
