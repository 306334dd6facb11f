"""The pianobot command line (typer). Each command parses, calls one library function, prints.

Command groups live in their own modules and register themselves on `app`. Only the module that
owns the invoked command is imported, so `pianobot runs` does not pay for scikit-learn.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys

import typer

from pianobot import __version__
from pianobot.cli.common import install_help_conventions, print_error
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
install_help_conventions()  # flags read as flags in every help page


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
    """Entry point: one-line errors and exit code 2 for bad input, never a traceback."""
    args = sys.argv[1:]
    _register(args[0] if args and not args[0].startswith("-") else None)
    try:
        app()
    except InputError as exc:
        print_error(str(exc))
        sys.exit(2)
