"""ProgressBar: a rich progress display subscribed to the runner (on stderr).

Shows trials done/total, the remaining time in *lab* time (on the sim rig the virtual clock runs
far ahead of the wall clock, and lab time is what a real sweep would take), retries so far and
the parameters of the current trial.
"""

from __future__ import annotations

import sys
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from pianobot.run.records import Record, RunEnded, RunStarted, TrialDone, TrialRetried, TrialStarted

_SHORT = {
    "vacuum_kpa": ("kPa", "{:g}"),
    "down_velocity_mps": ("m/s", "{:.3g}"),
    "acceleration_mps2": ("m/s²", "{:.3g}"),
    "depth_m": ("mm", "{:.3g}"),
}


def format_duration(seconds: float) -> str:
    """`3h05m`, `4m12s`, `9s`."""
    if not seconds == seconds or seconds < 0:
        return "?"
    total = int(round(seconds))
    hours, rest = divmod(total, 3600)
    minutes, secs = divmod(rest, 60)
    if hours:
        return f"{hours}h{minutes:02d}m"
    if minutes:
        return f"{minutes}m{secs:02d}s"
    return f"{secs}s"


def describe_parameters(parameters: dict[str, Any]) -> str:
    """The current trial's varied parameters in a few characters each."""
    parts = []
    for name, (unit, fmt) in _SHORT.items():
        if name in parameters:
            value = parameters[name] * (1000.0 if unit == "mm" else 1.0)
            parts.append(f"{fmt.format(value)} {unit}")
    return " · ".join(parts)


class ProgressBar:
    """Subscriber drawing a progress bar; use as a context manager around the run."""

    def __init__(self, console: Console | None = None) -> None:
        self.console = console or Console(file=sys.stderr)
        self.progress = Progress(
            TextColumn("[bold]{task.fields[name]}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("lab ETA {task.fields[eta]}"),
            TextColumn("retries {task.fields[retries]}"),
            TimeElapsedColumn(),
            TextColumn("{task.fields[current]}"),
            console=self.console,
            transient=False,
        )
        self._task: Any = None
        self._retries = 0
        self._session_start_lab_s: float | None = None
        self._session_done = 0
        self._total = 0
        self._done = 0

    def __enter__(self) -> ProgressBar:
        self.progress.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.progress.stop()

    def __call__(self, record: Record) -> None:
        if isinstance(record, RunStarted):
            self._total, self._done = record.planned, record.done
            self._task = self.progress.add_task(
                "sweep", total=record.planned, completed=record.done, name=record.run_id,
                eta="?", retries=0, current="",
            )
        elif self._task is None:
            return
        elif isinstance(record, TrialStarted):
            if self._session_start_lab_s is None:
                self._session_start_lab_s = record.t_s
            self.progress.update(self._task, current=describe_parameters(record.parameters))
        elif isinstance(record, TrialRetried):
            self._retries += 1
            self.progress.update(self._task, retries=self._retries)
        elif isinstance(record, TrialDone):
            if record.status != "failed":
                self._done += 1
                self._session_done += 1
            self.progress.update(self._task, completed=self._done, eta=self._eta(record.lab_time_s))
        elif isinstance(record, RunEnded):
            self.progress.update(self._task, current=record.status, eta="0s")

    def _eta(self, lab_time_s: float) -> str:
        """Lab time still needed, at the average lab time per trial of this session."""
        if self._session_start_lab_s is None or self._session_done == 0:
            return "?"
        per_trial_s = (lab_time_s - self._session_start_lab_s) / self._session_done
        return format_duration(per_trial_s * (self._total - self._done))
