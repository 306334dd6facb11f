"""Running a sweep: the runner, its records and subscribers, and `run_sweep`.

    outcome = run_sweep(Path("experiments/quickstart.yaml"), data_dir=Path("data"))

The runner publishes records (`pianobot.run.records`); the store sink, the progress bar and
test collectors subscribe to them.
"""

from __future__ import annotations

from pianobot.run.records import (
    BlockEnded,
    Record,
    RunEnded,
    RunStarted,
    Subscriber,
    TrialDone,
    TrialRetried,
    TrialStarted,
    TrialStopped,
)
from pianobot.run.rows import SampleChunk, TrialData, read_keystroke
from pianobot.run.runner import RetryPolicy, Runner, SessionResult
from pianobot.run.signals import StopControl
from pianobot.run.sweep import PreparedSweep, RunOutcome, dry_run, prepare_sweep, run_sweep

__all__ = [
    "BlockEnded",
    "PreparedSweep",
    "Record",
    "RetryPolicy",
    "RunEnded",
    "RunOutcome",
    "RunStarted",
    "Runner",
    "SampleChunk",
    "SessionResult",
    "StopControl",
    "Subscriber",
    "TrialData",
    "TrialDone",
    "TrialRetried",
    "TrialStarted",
    "TrialStopped",
    "dry_run",
    "prepare_sweep",
    "read_keystroke",
    "run_sweep",
]
