"""Progress of long work: the interface library code reports to, and the one display that draws it.

Library functions that can run for more than a few seconds take a `Progress` (default
`NO_PROGRESS`) and open one task per stage; they never print:

    def bootstrap(..., progress: Progress = NO_PROGRESS) -> ...:
        with progress.task("bootstrap refits", total=n) as task:
            for i in range(n):
                ...
                task.advance(note=f"keystroke set {i}")

The CLI passes `progress_display(enabled)`: a rich display on stderr with elapsed time and a
wall-clock ETA per task, or nothing at all under `--json` or when stderr is not a terminal.
Nested tasks (candidates inside an iteration) get their own row, removed when they finish.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:  # rich is imported only when a display is drawn
    from rich.console import Console


class Task(Protocol):
    """One stage of work with a known or unknown number of steps."""

    def advance(self, steps: float = 1, *, note: str | None = None) -> None:
        """Count `steps` more done; `note` says what is being worked on now."""

    def update(
        self, *, completed: float | None = None, total: float | None = None,
        note: str | None = None,
    ) -> None:
        """Set the count, the total (when it becomes known) or the note."""


class Progress(Protocol):
    """Where long work reports how far it is."""

    def task(
        self, description: str, total: float | None = None, completed: float = 0,
    ) -> AbstractContextManager[Task]:
        """Open a task: a context manager yielding the `Task` to advance.

        `completed` is work done before this session (a resumed sweep): it shows in the count
        but not in the rate, so the ETA is not fooled by it.
        """


class _NullTask:
    def advance(self, steps: float = 1, *, note: str | None = None) -> None:
        return None

    def update(
        self, *, completed: float | None = None, total: float | None = None,
        note: str | None = None,
    ) -> None:
        return None


class NullProgress:
    """Reports nowhere: the default for library calls and for `--json` or non-terminal output."""

    @contextmanager
    def task(
        self, description: str, total: float | None = None, completed: float = 0,
    ) -> Iterator[Task]:
        yield _NullTask()


NO_PROGRESS: Progress = NullProgress()


class _RichTask:
    def __init__(self, progress: Any, task_id: Any) -> None:
        self._progress = progress
        self._id = task_id

    def advance(self, steps: float = 1, *, note: str | None = None) -> None:
        fields = {} if note is None else {"note": note}
        self._progress.update(self._id, advance=steps, **fields)

    def update(
        self, *, completed: float | None = None, total: float | None = None,
        note: str | None = None,
    ) -> None:
        fields: dict[str, Any] = {}
        if completed is not None:
            fields["completed"] = completed
        if total is not None:
            fields["total"] = total
        if note is not None:
            fields["note"] = note
        self._progress.update(self._id, **fields)


class RichProgress:
    """A rich display on stderr: one row per open task, elapsed time and wall-clock ETA.

    The display starts with the first task and stops when the last open task ends. A task opened
    inside another is removed when it ends (the outer row keeps the summary); top-level rows stay
    on screen, so the terminal keeps a record of what ran and how long it took.
    """

    def __init__(self, console: Console | None = None) -> None:
        self._console = console
        self._display: Any = None
        self._open = 0

    @contextmanager
    def task(
        self, description: str, total: float | None = None, completed: float = 0,
    ) -> Iterator[Task]:
        display = self._start()
        nested = self._open > 0
        task_id = display.add_task(description, total=total, completed=completed, note="")
        self._open += 1
        try:
            yield _RichTask(display, task_id)
        finally:
            self._open -= 1
            if nested:
                display.remove_task(task_id)
            else:
                if total is not None:
                    display.update(task_id, completed=total)
            if self._open == 0:
                display.stop()
                self._display = None

    def _start(self) -> Any:
        if self._display is None:
            from pianobot.progress_rich import rich_display  # rich only when something is drawn

            self._display = rich_display(self._console or _stderr_console())
            self._display.start()
        return self._display


def _stderr_console() -> Console:
    from rich.console import Console

    return Console(file=sys.stderr)


def progress_display(enabled: bool, console: Console | None = None) -> Progress:
    """The display a command passes to library code: rich on a terminal, else nothing.

    Args:
        enabled: False under `--json` or `--no-progress`.
        console: where to draw (tests pass a recording console); default stderr, drawn only
            when stderr is a terminal.
    """
    if not enabled:
        return NO_PROGRESS
    if console is None and not sys.stderr.isatty():
        return NO_PROGRESS
    return RichProgress(console)
