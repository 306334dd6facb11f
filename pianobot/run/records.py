"""The records a runner publishes; subscribers (store, progress bar, tests) consume them.

The runner never writes files or draws bars itself (bluesky's callbacks pattern): it emits a
`RunStarted`, then per trial `TrialStarted`, zero or more `TrialRetried`, and one of
`TrialDone` / `TrialFailed` / `TrialStopped`, and finally `RunEnded`. On a rig that works out
blocks of keystrokes ahead (the simulator), each block ends with a `BlockEnded`. A keystroke
whose note-on was lost is `TrialDone` (failed) then `TrialRetried`; its trial starts again,
with the next attempt, after the last planned one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

from pianobot.run.rows import TrialData

if TYPE_CHECKING:
    from pianobot.store import StagedPart


@dataclass(frozen=True)
class RunStarted:
    """A run (or a resumed part of it) begins."""

    run_id: str
    planned: int  # trials in the plan
    done: int  # trials already completed (a resume)
    todo: int  # trials this session will attempt
    resumed: bool
    blocks: bool = False  # trials come in blocks, each closed by a `BlockEnded`
    warnings: tuple[str, ...] = ()  # what the rig found when it opened, before any motion


@dataclass(frozen=True)
class TrialStarted:
    """A trial's attempt is about to move the arm."""

    trial_id: str
    index: int
    attempt: int
    parameters: dict[str, Any]
    t_s: float  # run clock


@dataclass(frozen=True)
class TrialRetried:
    """An attempt failed with a transient fault; the runner reconnects and tries again."""

    trial_id: str
    index: int
    attempt: int  # the attempt that failed
    error: str
    backoff_s: float
    t_s: float


@dataclass(frozen=True)
class TrialDone:
    """A keystroke was executed: its trial row (ok | silent | failed), samples and MIDI."""

    data: TrialData
    lab_time_s: float  # run clock after the keystroke

    @property
    def trial_id(self) -> str:
        return self.data.trial_id

    @property
    def status(self) -> str:
        return self.data.status


@dataclass(frozen=True)
class TrialStopped:
    """A safety stop interrupted the trial; it was not completed and will be redone on resume."""

    trial_id: str
    index: int
    attempt: int
    reason: str
    t_s: float


@dataclass(frozen=True)
class BlockEnded:
    """A block of trials worked out together (a simulated rig) is through: store it as one part."""

    trials: int  # trials of the block that were run
    lab_time_s: float
    # The block's parts already encoded by a worker (table name -> Parquet bytes, or the part
    # the worker staged in the run folder), or None when the store writes the block from the
    # trials' records itself.
    parts: dict[str, bytes | StagedPart] | None = None


@dataclass(frozen=True)
class RunEnded:
    """The session ends: completed, stopped (safety), interrupted (signal) or failed."""

    status: str
    reason: str | None
    lab_time_s: float
    done: int  # trials completed over the whole run
    retries: int  # retries in this session


Record = RunStarted | TrialStarted | TrialRetried | TrialDone | TrialStopped | BlockEnded | RunEnded


class Subscriber(Protocol):
    """Anything that wants the runner's records (called in order, in the runner's thread)."""

    def __call__(self, record: Record) -> None: ...
