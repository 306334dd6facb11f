"""The pianobot command line (typer). Each command parses, calls one library function, prints.

Command groups live in their own modules and register themselves on `app`.
"""

from __future__ import annotations

import sys

import typer

from pianobot.cli.common import print_error
from pianobot.errors import InputError

app = typer.Typer(
    name="pianobot",
    help="Robotic piano keystroke experiments: sweep, import, identify, fit, report, discover, play.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)


def _register() -> None:
    """Every module in this package that defines `register(app)` adds its commands."""
    import importlib
    import pkgutil

    import pianobot.cli as package

    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"pianobot.cli.{info.name}")
        register = getattr(module, "register", None)
        if callable(register):
            register(app)


def main() -> None:
    """Entry point: one-line errors and exit code 2 for bad input, never a traceback."""
    _register()
    try:
        app()
    except InputError as exc:
        print_error(str(exc))
        sys.exit(2)
