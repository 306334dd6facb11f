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
from pianobot.cli.common import install_help_conventions, loading_row, print_error
from pianobot.errors import InputError

app = typer.Typer(
    name="pianobot",
    help="Robotic piano keystroke experiments: sweep, import, identify, fit, report, discover, play.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)

# The CLI's table of contents: each top-level command, the module that owns it, and its
# one-line help (kept equal to the command's own by tests/cli/test_startup.py). `--version`,
# `--help` and a bare `pianobot` are answered from this table alone, without importing any
# command module: those pull in pandas, scipy or scikit-learn and take seconds to load.
COMMANDS: dict[str, tuple[str, str]] = {
    "sweep": ("sweep", "Run an experiment spec on its rig into data/runs/<run_id>/ (or --dry-run it)."),
    "runs": ("runs", "List runs, or show one run."),
    "import": ("imports", "Import old data (keystroke logs, force logs, Motive mocap CSV) as runs."),
    "rig": ("rig", "The lab rig: reach every device (`check`), teach the reference pose (`calibrate`)."),
    "model": ("model", "Inspect the keystroke model: resonance, one simulated keystroke."),
    "identify": ("analysis", "Identify the keystroke model from mocap trajectories; write a model file with intervals."),
    "fit": ("analysis", "Cross-validate learned maps to on-velocity, hold and silence; save each as a predictor."),
    "report": ("analysis", "Write one self-contained HTML report (figures embedded, no network)."),
    "discover": ("discover", "Localise where the model and the measurements disagree, name the missing effect, refit."),
    "play": ("play", "Warm up on the piano, play a MIDI song at a tempo the finger can keep, and score it."),
}
COMMAND_MODULES: dict[str, str] = {name: module for name, (module, _) in COMMANDS.items()}
_registered: set[str] = set()
install_help_conventions()  # flags read as flags in every help page


def _version(value: bool) -> None:
    if value:
        print(f"pianobot {__version__}")
        raise typer.Exit()


def _root(
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    """Robotic piano keystroke experiments on a simulated or real rig."""


app.callback()(_root)


def _table_of_contents() -> typer.Typer:
    """The top-level app with every command listed from `COMMANDS` (nothing imported)."""
    toc = typer.Typer(name=app.info.name, help=app.info.help, no_args_is_help=True,
                      pretty_exceptions_enable=False, add_completion=False)
    toc.callback()(_root)
    for name, (_, text) in COMMANDS.items():
        toc.command(name, help=text, context_settings={"ignore_unknown_options": True})(_unloaded)
    return toc


def _unloaded() -> None:  # pragma: no cover - never run: a real command replaces it
    raise RuntimeError("command module not loaded")


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
    command = args[0] if args and args[0] in COMMANDS else None
    if command is None:
        # --version, --help, no arguments or an unknown command: the table of contents answers.
        _table_of_contents()()
        return
    with loading_row(f"{command}: loading", args):
        _register(command)
    try:
        app()
    except InputError as exc:
        print_error(str(exc))
        sys.exit(2)
