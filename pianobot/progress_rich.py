"""The one drawing of progress: a rich display on stderr, one line per task, fit to the terminal.

Columns: spinner, what is being done, bar, done/total, elapsed, wall-clock ETA, and a note (the
current item, a sweep's lab-time ETA). On a narrow terminal the description and the note give
way (cut with "…"); counts and times never do.
"""

from __future__ import annotations

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    SpinnerColumn,
    Task,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Column
from rich.text import Text


class ShrinkingText(ProgressColumn):
    """A task's description or a field, on one line, cut with "…" when the row is too wide.

    Rich shrinks only columns that may wrap, so the column may; the text itself never wraps.
    """

    def __init__(self, field: str, style: str) -> None:
        super().__init__(table_column=Column(no_wrap=False, overflow="ellipsis"))
        self._field = field
        self._style = style

    def render(self, task: Task) -> Text:
        value = task.description if self._field == "description" else task.fields.get(self._field, "")
        return Text(str(value), style=self._style, no_wrap=True, overflow="ellipsis")


def rich_display(console: Console) -> Progress:
    """A (not yet started) rich Progress with pianobot's columns, drawing on `console`."""
    return Progress(
        SpinnerColumn(),
        ShrinkingText("description", "bold"),
        BarColumn(bar_width=12),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        ShrinkingText("note", "dim"),
        console=console,
        transient=False,
    )
