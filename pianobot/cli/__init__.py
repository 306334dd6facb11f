"""The pianobot command line (typer). Each command parses, calls one library function, prints.

Command groups live in their own modules and register themselves on `app`. Only the module that
owns the invoked command is imported, so `pianobot runs` does not pay for scikit-learn.
"""

from __future__ import annotations

import difflib
import importlib
import math
import os
import pkgutil
import sys

import typer

# typer carries its own copy of click; its exceptions are what the app raises.
from typer._click import exceptions as click_errors

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
    "runs": ("runs", "List runs; show, check or repair one run."),
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
    """Entry point: one-line errors and exit code 2 for bad input, never a traceback.

    Bad input is an InputError (a spec, a file, a run), a command-line usage error (an unknown
    option, `--seed x`), or a file the system refuses (a folder where a file belongs, a
    read-only folder, a full disk): each gets one line on stderr and exit code 2.
    """
    args = sys.argv[1:]
    command = args[0] if args and args[0] in COMMANDS else None
    if command is None and args and not args[0].startswith("-"):
        print_error(_unknown_command(args[0]))
        sys.exit(2)
    if command is None:
        # --version, --help or no arguments: the table of contents answers.
        try:
            _table_of_contents()(standalone_mode=False)
        except click_errors.NoArgsIsHelpError:
            sys.exit(2)  # `pianobot` alone: the help has been shown
        except click_errors.UsageError as exc:  # `pianobot --bogus`
            print_error(f"pianobot: {exc.format_message()} (see --help)")
            sys.exit(2)
        return
    try:
        with loading_row(f"{command}: loading", args):
            _register(command)
    except KeyboardInterrupt:  # Ctrl-C while the command's modules load: nothing has started
        print_error("interrupted")
        sys.exit(130)
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


def _unknown_command(name: str) -> str:
    """`no command 'swep' (did you mean 'sweep'?); commands: sweep, runs, ...`"""
    close = difflib.get_close_matches(name, list(COMMANDS), n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    return f"pianobot: no command {name!r}{hint}; commands: {', '.join(COMMANDS)} (see --help)"


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
