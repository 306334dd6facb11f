"""The pianobot command line (typer). Each command parses, calls one library function, prints.

Command groups live in their own modules and register themselves on `app`. Only the module that
owns the invoked command is imported, so `pianobot runs` does not pay for scikit-learn.
"""

from __future__ import annotations

import importlib
import math
import os
import pkgutil
import sys

import typer

# typer carries its own copy of click; its exceptions are what the app raises.
from typer._click import exceptions as click_errors

from pianobot import __version__
from pianobot.cli.common import print_error
from pianobot.errors import InputError

app = typer.Typer(
    name="pianobot",
    help="Robotic piano keystroke experiments: sweep, import, identify, fit, report, discover, play.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)

# Which module holds each top-level command (the CLI's table of contents).
COMMAND_MODULES: dict[str, str] = {
    "sweep": "sweep",
    "runs": "sweep",
    "import": "imports",
    "rig": "rig",
    "model": "model",
    "identify": "analysis",
    "fit": "analysis",
    "report": "analysis",
    "discover": "discover",
    "play": "play",
}
_registered: set[str] = set()


def _version(value: bool) -> None:
    if value:
        print(f"pianobot {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    """Robotic piano keystroke experiments on a simulated or real rig."""


def _all_modules() -> set[str]:
    import pianobot.cli as package

    return {info.name for info in pkgutil.iter_modules(package.__path__) if info.name != "common"}


def _register(command: str | None = None) -> None:
    """Add the commands of the module that owns `command`, or of every module."""
    wanted = {COMMAND_MODULES[command]} if command in COMMAND_MODULES else _all_modules()
    for name in sorted(wanted - _registered):
        module = importlib.import_module(f"pianobot.cli.{name}")
        register = getattr(module, "register", None)
        if callable(register):
            register(app)
        _registered.add(name)


def main() -> None:
    """Entry point: one-line errors and exit code 2 for bad input, never a traceback.

    Bad input is an InputError (a spec, a file, a run), a command-line usage error (an unknown
    option, `--seed x`), or a file the system refuses (a folder where a file belongs, a
    read-only folder, a full disk): each gets one line on stderr and exit code 2.
    """
    args = sys.argv[1:]
    _register(args[0] if args and not args[0].startswith("-") else None)
    try:
        _refuse_non_finite_options(args)
        code = app(standalone_mode=False)
    except InputError as exc:
        print_error(str(exc))
        sys.exit(2)
    except click_errors.NoArgsIsHelpError:
        sys.exit(2)  # `pianobot` alone: typer has shown the help
    except click_errors.UsageError as exc:
        where = f"{exc.ctx.command_path}: " if exc.ctx is not None else ""
        print_error(f"{where}{exc.format_message()} (see --help)")
        sys.exit(exc.exit_code)
    except click_errors.ClickException as exc:
        print_error(exc.format_message())
        sys.exit(exc.exit_code)
    except typer.Abort:
        print_error("aborted")
        sys.exit(130)
    except OSError as exc:
        if os.environ.get("PIANOBOT_TRACEBACK"):
            raise
        print_error(_os_error_text(exc))
        sys.exit(2)
    except MemoryError:
        print_error("out of memory: the input is too large for this machine")
        sys.exit(2)
    sys.exit(code if isinstance(code, int) else 0)


def _refuse_non_finite_options(args: list[str]) -> None:
    """No option value may be NaN or infinite (`--gain-n nan`, `--min-coverage inf`, `1e999`).

    Every number a command takes is a physical quantity or a count; typer would accept "nan"
    for any float option and the command would store nonsense. Checked for all commands here,
    before any of them runs.
    """
    for i, arg in enumerate(args):
        if not arg.startswith("--"):
            continue
        name, sep, value = arg.partition("=")
        if not sep:
            if i + 1 >= len(args) or args[i + 1].startswith("--"):
                continue
            value = args[i + 1]
        try:
            number = float(value)
        except ValueError:
            continue
        if not math.isfinite(number):
            raise InputError(f"must be a finite number, got {value!r}", name)


def _os_error_text(exc: OSError) -> str:
    """`data/runs: Permission denied` from any OSError (the file and what the system said)."""
    what = exc.strerror or str(exc) or type(exc).__name__
    where = exc.filename if exc.filename is not None else None
    return f"{where}: {what}" if where is not None else what
