"""Options and output helpers shared by every command: flags, JSON, consoles and tables.

Tables go through `print_table` (or `print_fields` for key → value lists): it fits the terminal
by wrapping prose columns and, when even that is not enough, dropping the columns a command
marked as least important (a dim line says which; `--json` always has everything). Numbers and
run ids are never cut with "…".
"""

from __future__ import annotations

import inspect
import json
import math
import os
import re
import sys
import textwrap
from collections.abc import Iterator, Sequence
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, NoReturn

import typer
from rich import box
from rich.cells import cell_len
from rich.console import Console, JustifyMethod
from rich.table import Table
from rich.text import Text

from pianobot.errors import InputError
from pianobot.output import can_create_in
from pianobot.progress import Progress, progress_display

DataDir = Annotated[
    Path, typer.Option("--data", help="Dataset folder (runs live in DIR/runs/).", show_default=True)
]
JsonFlag = Annotated[
    bool, typer.Option("--json", help="Machine-readable JSON on stdout (no tables, no progress).")
]
NoProgressFlag = Annotated[bool, typer.Option("--no-progress", help="No progress display on stderr.")]
RunId = Annotated[str, typer.Argument(help="Run id or a unique prefix.")]
RunIds = Annotated[list[str], typer.Argument(help="Run ids (or unique prefixes).")]
PressesOption = Annotated[Path | None, typer.Option(
    "--presses", help="CSV of the commanded presses (t_start_s, speeds, acceleration, depth, distance, "
                      "hold) for runs that do not record them, e.g. an imported Motive take.")]
DEFAULT_DATA = Path("data")
PIPE_WIDTH = 200  # piped output is read by programs and pagers, not wrapped for a terminal
_FLAG_VALUES = frozenset({"true", "false", "yes", "no", "on", "off"})


def print_error(message: str) -> None:
    """One line on stderr, no traceback."""
    first = " ".join(message.split())
    print(f"error: {first}", file=sys.stderr)


def fail(message: str) -> NoReturn:
    """Report bad input and exit with code 2."""
    print_error(message)
    raise typer.Exit(code=2)


def print_warning(message: str) -> None:
    """One `warning:` line on stderr (stdout stays clean for tables and JSON)."""
    print(f"warning: {' '.join(message.split())}", file=sys.stderr)


def warn_unfinished(runs: Sequence[str], data: Path) -> None:
    """Before an analysis: a warning for each run that is still being recorded, died without
    finishing or was stopped early (its numbers cover only what it recorded so far). A run that
    cannot be opened or is damaged is left to the command, which refuses it in one line."""
    from pianobot.store import load_run, unfinished_note

    for run_id in dict.fromkeys(runs):
        try:
            note = unfinished_note(load_run(run_id, data))
        except InputError:
            continue
        if note is not None:
            print_warning(note)


#: The strongest gauge vacuum (kPa below atmosphere) a value may state.
MAX_VACUUM_KPA = 100.0


def check_vacuum_option(value: float | None, option: str = "--vacuum-kpa") -> None:
    """InputError unless `value` is None or a gauge vacuum a pump reaches (|value| ≤ 100 kPa; a
    magnitude, e.g. 40, is read as −40 kPa by the commands, as the study's logs store it)."""
    if value is not None and not (math.isfinite(value) and abs(value) <= MAX_VACUUM_KPA):
        raise InputError(f"vacuum is a gauge pressure in [-{MAX_VACUUM_KPA:g}, 0] kPa, got {value:g}", option)


def writable(path: Path | None, option: str) -> Path | None:
    """Check before any work that `path`'s folder exists or can be made, so a long command
    does not fail at its very end (or after storing a run) on a typo in an output path."""
    if path is None:
        return None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the folder of {path} ({exc.strerror})", option) from None
    if path.is_dir():
        raise InputError(f"{path} is a folder; give a file name", option)
    if not can_create_in(path.parent):
        raise InputError(f"cannot write in {path.parent} (read-only?)", option)
    return path


def writable_folder(folder: Path, option: str) -> Path:
    """Check before any work that `folder` is, or can be made, a folder files can be written in
    (`fit --out-dir` used to fail after its cross-validation, with the system's words)."""
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{folder} is a file; give a folder", option)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the folder {folder} ({exc.strerror})", option) from None
    if not can_create_in(folder):
        raise InputError(f"cannot write in {folder} (read-only?)", option)
    return folder


def figure_path(path: Path | None, option: str = "--plot") -> Path | None:
    """`writable`, and a file type matplotlib writes (png, pdf, svg, ...): checked before any
    work, so a figure named `roll.txt` does not fail after the robot has played."""
    if path is None:
        return None
    from matplotlib.backend_bases import FigureCanvasBase

    kinds = FigureCanvasBase.get_supported_filetypes()
    kind = path.suffix.lower().lstrip(".")
    if kind not in kinds:
        named = f"'.{kind}'" if kind else "no extension"
        raise InputError(f"{path} has {named}; a figure is one of .{', .'.join(sorted(kinds))}", option)
    return writable(path, option)


def emit_json(payload: Any) -> None:
    """Print JSON on stdout (NaN and ±inf become null so every consumer can parse it)."""
    print(json.dumps(_clean(payload), indent=2, default=str))


def _clean(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None  # JSON has no NaN or Infinity: strict parsers (JSON.parse, json.loads(strict)) refuse them
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    if hasattr(value, "item") and callable(value.item):  # numpy scalars
        return _clean(value.item())
    return value


@contextmanager
def loading_row(what: str, args: Sequence[str], *, delay_s: float = 1.0) -> Iterator[None]:
    """A progress row while a command's libraries load (scikit-learn, scipy, matplotlib: seconds
    on a busy machine), drawn only when loading takes longer than `delay_s`, so a quick command
    stays clean. Off under --json, --no-progress, --help or without a terminal, like all progress.
    """
    if not sys.stderr.isatty() or {"--json", "--no-progress", "--help"} & set(args):
        yield
        return
    import threading

    import pianobot.progress_rich  # noqa: F401  # loaded here, not in the drawing thread

    progress = progress_display(True)
    lock = threading.Lock()
    opened: list[AbstractContextManager[object]] = []
    finished = False

    def start() -> None:
        with lock:
            if not finished:
                row = progress.task(what)
                row.__enter__()
                opened.append(row)

    timer = threading.Timer(delay_s, start)
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        with lock:
            finished = True
        timer.cancel()
        for row in opened:
            row.__exit__(None, None, None)


def command_progress(json_out: bool, no_progress: bool = False) -> Progress:
    """The progress a command passes to library code: the shared display on stderr, or nothing
    under --json, --no-progress, or when stderr is not a terminal."""
    return progress_display(not (json_out or no_progress))


# --- consoles -----------------------------------------------------------------------------------


def _bounded() -> bool:
    """True when output has a width to fit: a terminal, or COLUMNS set by the user or a test."""
    return sys.stdout.isatty() or os.environ.get("COLUMNS", "").isdigit()


def output_console() -> Console:
    """The console for a command's human output on stdout (no repr highlighting of numbers)."""
    return Console(highlight=False) if _bounded() else Console(highlight=False, width=PIPE_WIDTH)


def say(text: str) -> None:
    """Plain output wrapped at spaces to the terminal; a path or id longer than the line is left
    whole on its own line (still copyable), never folded or cut. Piped output is not wrapped."""
    if not _bounded():
        print(text)
        return
    width = output_console().width
    indent = " " * (len(text) - len(text.lstrip(" ")) + 2)  # continuation lines hang under the text
    print(textwrap.fill(text, width, subsequent_indent=indent, break_long_words=False,
                        break_on_hyphens=False))


def say_written(what: str, path: Path | str) -> None:
    """Tell the user where a file went: `model written to models/x.json`."""
    say(f"{what} written to {path}")


# --- tables -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Column:
    """One column of a terminal table.

    Args:
        header: heading, with its unit (`hold RMSE (ms)`); it may wrap at spaces.
        priority: 0 = always shown; on a narrow terminal the highest number goes first.
        justify: `right` for numbers.
        wrap: prose (reasons, notes, paths) wraps and folds; anything else is never cut.
    """

    header: str
    priority: int = 0
    justify: JustifyMethod = "left"
    wrap: bool = False


Cell = str | Text
_PROSE_COMFORT = 24  # a prose column narrower than this reads badly: drop other columns first
_PROSE_MIN = 12  # narrowest a prose column is squeezed to when nothing else can go


def _words_len(text: str) -> int:
    return max((cell_len(w) for w in text.split()), default=0)


def _plain(cell: Cell) -> str:
    return cell.plain if isinstance(cell, Text) else cell


def _bounds(column: Column, cells: Sequence[str], prose_min: int) -> tuple[int, int]:
    """(narrowest, natural) content width of a column; prose may go down to `prose_min`."""
    natural = max([cell_len(column.header),
                   *(cell_len(line) for c in cells for line in c.splitlines() or [""])])
    narrowest = _words_len(column.header)
    for c in cells:
        if column.wrap:
            narrowest = max(narrowest, min(max(_words_len(c), prose_min), cell_len(c)))
        else:
            narrowest = max(narrowest, cell_len(c))
    return narrowest, natural


def _extra(n_columns: int) -> int:
    # box.SIMPLE_HEAD without edges: a separator and a space of padding each side between columns
    return 3 * (n_columns - 1)


def fit_columns(columns: Sequence[Column], rows: Sequence[Sequence[Cell]],
                width: int) -> tuple[list[int], list[int]]:
    """Which columns to show and their content widths, to fit `width` terminal cells.

    Low-priority columns go before prose is squeezed below a comfortable width; numbers and
    ids are never narrower than their longest cell (a table too narrow even then folds them).
    """
    kept = list(range(len(columns)))

    def bounds(prose_min: int) -> list[tuple[int, int]]:
        return [_bounds(columns[i], [_plain(r[i]) for r in rows], prose_min) for i in kept]

    while True:
        comfortable = bounds(_PROSE_COMFORT)
        space = width - _extra(len(kept))
        droppable = [i for i in kept if columns[i].priority > 0]
        if sum(b[0] for b in comfortable) <= space:
            return kept, _share(comfortable, space)
        if not droppable:
            return kept, _share(bounds(_PROSE_MIN), space)
        worst = max(columns[i].priority for i in droppable)
        kept.remove([i for i in droppable if columns[i].priority == worst][-1])


def _share(bounds: list[tuple[int, int]], space: int) -> list[int]:
    """Natural widths if they fit, else each column's narrowest plus a fair share of the rest."""
    widths = [natural for _, natural in bounds]
    if sum(widths) <= space:
        return widths
    widths = [narrowest for narrowest, _ in bounds]
    spare = space - sum(widths)
    while spare > 0:
        short = [i for i, (_, natural) in enumerate(bounds) if widths[i] < natural]
        if not short:
            break
        i = max(short, key=lambda j: bounds[j][1] - widths[j])
        widths[i] += 1
        spare -= 1
    return widths


def print_table(columns: Sequence[Column], rows: Sequence[Sequence[Cell]], *, title: str | None = None,
                show_header: bool = True, console: Console | None = None) -> list[str]:
    """Print a table that fits the terminal; returns the headers of the columns left out."""
    rows = [list(r) for r in rows]
    if console is None:
        console = output_console()
        if not _bounded():  # piped: as wide as the table needs
            natural = sum(_bounds(c, [_plain(r[i]) for r in rows], 0)[1] for i, c in enumerate(columns))
            console = Console(highlight=False, width=max(80, natural + _extra(len(columns))))
    kept, widths = fit_columns(columns, rows, console.width)
    if title:  # its own line: a title inside a narrow table would wrap to the table's width
        console.print(Text(title, style="bold"))
    table = Table(box=box.SIMPLE_HEAD, show_edge=False, pad_edge=False, show_header=show_header,
                  highlight=False)
    for i, width in zip(kept, widths, strict=True):
        c = columns[i]
        # Widths already hold every unbreakable cell whole, so rich may wrap freely: headings
        # wrap at spaces, prose wraps, and a path longer than its column folds instead of "…".
        table.add_column(c.header, justify=c.justify, width=width, overflow="fold")
    for r in rows:
        table.add_row(*(r[i] for i in kept))
    console.print(table)
    dropped = [columns[i].header for i in range(len(columns)) if i not in kept]
    if dropped:
        console.print(f"[dim]not shown at {console.width} columns: {', '.join(dropped)} "
                      "(a wider terminal or --json shows them)[/dim]", highlight=False)
    return dropped


def print_fields(fields: Sequence[tuple[str, Any]], *, title: str | None = None,
                 console: Console | None = None) -> None:
    """A key → value list (provenance, a summary); long values wrap, ids and paths fold."""
    rows = [[key, value if isinstance(value, Text) else str(value)] for key, value in fields]
    print_table([Column("", 0), Column("", 0, wrap=True)], rows, title=title, show_header=False,
                console=console)


# --- help pages and flags -----------------------------------------------------------------------


def install_help_conventions() -> None:
    """Make every boolean flag read as a flag: no `<bool>` in help, `--json true` refused.

    Typer prints a `<bool>` type after flags, which makes `--json true` look valid; the stray
    `true` then becomes a run id or a command name and fails far from its cause. Applied once,
    to every command and group (including --help and --version), so new flags get it for free.
    """
    from typer.core import TyperCommand, TyperGroup, TyperOption

    if getattr(TyperOption, "_pianobot_flags", False):
        return
    show_type = TyperOption.display_type_rich

    def display_type_rich(self: TyperOption, ctx: Any) -> str | None:
        return None if self.is_flag else show_type(self, ctx)

    TyperOption.display_type_rich = display_type_rich  # type: ignore[method-assign]
    TyperOption._pianobot_flags = True  # type: ignore[attr-defined]
    for cls in (TyperCommand, TyperGroup):
        cls.parse_args = _refusing_flag_values(cls.parse_args)  # type: ignore[method-assign]
        cls.format_help = _reflowing_help(cls.format_help)  # type: ignore[method-assign]


def reflow(text: str) -> str:
    """Join a docstring's hard-wrapped lines so the terminal wraps each paragraph itself.

    Typer's rich help keeps the source's line breaks, so a docstring wrapped at 100 columns
    shows on an 80-column terminal as one full line and one stub. Lists (`- `, `* `, `1. `) and
    indented blocks keep their lines.
    """
    paragraphs = []
    for paragraph in text.split("\n\n"):
        lines = paragraph.splitlines()
        if any(_LIST_LINE.match(line) for line in lines):
            paragraphs.append(paragraph)
        else:
            paragraphs.append(" ".join(line.strip() for line in lines))
    return "\n\n".join(paragraphs)


_LIST_LINE = re.compile(r"^\s*([-*•]|\d+[.)])\s|^\s{2,}\S|^\x08")


def _reflowing_help(format_help: Any) -> Any:
    def format(self: Any, ctx: Any, formatter: Any) -> Any:
        if self.help:
            self.help = reflow(inspect.cleandoc(self.help))
        return format_help(self, ctx, formatter)

    return format


def _refusing_flag_values(parse_args: Any) -> Any:
    def parse(self: Any, ctx: Any, args: list[str]) -> list[str]:
        flags = {o for p in self.get_params(ctx) if getattr(p, "is_flag", False) for o in p.opts}
        for flag, value in zip(args, args[1:], strict=False):
            if flag == "--":
                break
            if flag in flags and value.lower() in _FLAG_VALUES:
                fail(f"{flag} is a flag and takes no value: drop {value!r} "
                     f"(write {flag} to turn it on, leave it out to keep it off)")
        return list(parse_args(self, ctx, args))

    return parse
