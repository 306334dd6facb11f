"""ProgressBar: the runner's records shown through the shared progress display (on stderr).

One task per session: trials done/total with the wall-clock ETA the shared display computes,
and a note with the remaining *lab* time (on the sim rig the virtual clock runs far ahead of the
wall clock, and lab time is what the real rig would take), retries so far and the current
trial's parameters. A resumed run counts the trials done before without letting them speed up
the ETA.
"""

from __future__ import annotations

from contextlib import AbstractContextManager, ExitStack
from typing import Any

from pianobot.durations import format_duration
from pianobot.progress import Progress, Task, progress_display
from pianobot.run.records import Record, RunEnded, RunStarted, TrialDone, TrialRetried, TrialStarted
from pianobot.spec.parameters import PARAMETERS


def describe_parameters(parameters: dict[str, Any]) -> str:
    """The current trial's headline parameters (the table's `in_progress`) in a few characters each."""
    parts = []
    for p in PARAMETERS.values():
        if p.in_progress and p.name in parameters:
            parts.append(f"{parameters[p.name] * p.display_scale:.3g} {p.display_unit}")
    return " · ".join(parts)


def stage(enabled: bool, description: str) -> AbstractContextManager[Task]:
    """A row for work before the trials start (expanding the plan, opening the rig): seconds on a
    large spec or a cold simulator, which would otherwise pass in silence."""
    return progress_display(enabled).task(f"sweep: {description}")


class ProgressBar:
    """Subscriber drawing a sweep's progress; use as a context manager around the run.

    Args:
        progress: where to draw; default the shared display on stderr (nothing when stderr is
            not a terminal).
    """

    def __init__(self, progress: Progress | None = None) -> None:
        self._progress = progress if progress is not None else progress_display(True)
        self._stack = ExitStack()
        self._task: Task | None = None
        self._retries = 0
        self._session_start_lab_s: float | None = None
        self._session_done = 0
        self._total = 0
        self._done = 0
        self._lab_eta = "?"
        self._current = ""

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exc: object) -> None:
        self._stack.close()

    def __call__(self, record: Record) -> None:
        if isinstance(record, RunStarted):
            self._total, self._done = record.planned, record.done
            self._task = self._stack.enter_context(
                self._progress.task("sweep", total=record.planned, completed=record.done))
            self._show()
            return
        task = self._task
        if task is None:
            return
        if isinstance(record, TrialStarted):
            if self._session_start_lab_s is None:
                self._session_start_lab_s = record.t_s
            self._current = describe_parameters(record.parameters)
            self._show()
        elif isinstance(record, TrialRetried):
            self._retries += 1
            self._show()
        elif isinstance(record, TrialDone):
            if record.status != "failed":
                self._done += 1
                self._session_done += 1
            self._lab_eta = self._eta(record.lab_time_s)
            task.update(completed=self._done)
            self._show()
        elif isinstance(record, RunEnded):
            self._lab_eta, self._current = "0 s", record.status
            self._show()

    def _show(self) -> None:
        if self._task is None:
            return
        parts = [f"lab {self._lab_eta} left"]
        if self._retries:
            parts.append(f"{self._retries} {'retry' if self._retries == 1 else 'retries'}")
        if self._current:
            parts.append(self._current)
        self._task.update(note=" · ".join(parts))

    def _eta(self, lab_time_s: float) -> str:
        """Lab time still needed, at the average lab time per trial of this session."""
        if self._session_start_lab_s is None or self._session_done == 0:
            return "?"
        per_trial_s = (lab_time_s - self._session_start_lab_s) / self._session_done
        return format_duration(per_trial_s * (self._total - self._done))
