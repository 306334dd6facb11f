"""The one drawing of progress: a rich display on stderr, one line per task, fit to the terminal.

Columns: spinner, what is being done, bar, done/total, elapsed, wall-clock ETA, and a note (the
current item, a sweep's lab-time ETA); a stage of unknown length shows no count and no ETA. On a narrow terminal the description and the note give
way (cut with "…"); counts and times never do.
"""

from __future__ import annotations

from rich.console import Console, RenderableType
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


class Counted(ProgressColumn):
    """A column that only means something with a known total (count, ETA): blank without one,
    so a stage of unknown length reads "spinner, what, pulse, elapsed" and not "0/? ETA -:--:--"."""

    def __init__(self, inner: ProgressColumn) -> None:
        super().__init__(table_column=inner.get_table_column())
        self._inner = inner

    def render(self, task: Task) -> RenderableType:
        return self._inner.render(task) if task.total is not None else Text("")


def rich_display(console: Console) -> Progress:
    """A (not yet started) rich Progress with pianobot's columns, drawing on `console`."""
    return Progress(
        SpinnerColumn(),
        ShrinkingText("description", "bold"),
        BarColumn(bar_width=12),
        Counted(MofNCompleteColumn()),
        TimeElapsedColumn(),
        Counted(TextColumn("ETA")),
        Counted(TimeRemainingColumn()),
        ShrinkingText("note", "dim"),
        console=console,
        transient=False,
    )
