"""The shared progress interface: silent by default, drawn on a console when enabled."""

from __future__ import annotations

import io

from rich.console import Console

from pianobot.progress import NO_PROGRESS, RichProgress, progress_display


def _console() -> tuple[Console, io.StringIO]:
    buffer = io.StringIO()
    return Console(file=buffer, force_terminal=True, width=100), buffer


def test_disabled_display_is_the_null_progress() -> None:
    console, buffer = _console()
    progress = progress_display(False, console)
    assert progress is NO_PROGRESS
    with progress.task("fits", total=3) as task:
        task.advance(note="one")
        task.update(total=4, completed=2)
    assert buffer.getvalue() == ""


def test_rich_display_draws_description_count_and_note() -> None:
    console, buffer = _console()
    progress = progress_display(True, console)
    assert isinstance(progress, RichProgress)
    with progress.task("bootstrap refits", total=4) as task:
        for i in range(4):
            task.advance(note=f"set {i}")
    text = buffer.getvalue()
    assert "bootstrap refits" in text
    assert "4/4" in text
    assert "ETA" in text


def test_nested_task_row_is_removed_and_display_stops() -> None:
    console, _ = _console()
    progress = RichProgress(console)
    with progress.task("iterations", total=2) as outer:
        with progress.task("candidates", total=3) as inner:
            inner.advance(3)
        display = progress._display
        assert display is not None
        assert [t.description for t in display.tasks] == ["iterations"]
        outer.advance()
    assert progress._display is None
