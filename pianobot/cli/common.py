"""Options and output helpers shared by every command."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated, Any, NoReturn

import typer

DataDir = Annotated[
    Path, typer.Option("--data", help="Dataset folder (runs live in DIR/runs/).", show_default=True)
]
JsonFlag = Annotated[bool, typer.Option("--json", help="Machine-readable JSON on stdout.")]
DEFAULT_DATA = Path("data")


def print_error(message: str) -> None:
    """One line on stderr, no traceback."""
    first = " ".join(message.split())
    print(f"error: {first}", file=sys.stderr)


def fail(message: str) -> NoReturn:
    """Report bad input and exit with code 2."""
    print_error(message)
    raise typer.Exit(code=2)


def emit_json(payload: Any) -> None:
    """Print JSON on stdout (NaN becomes null so every consumer can parse it)."""
    print(json.dumps(_clean(payload), indent=2, default=str))


def _clean(value: Any) -> Any:
    if isinstance(value, float) and value != value:
        return None
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    if hasattr(value, "item") and callable(value.item):  # numpy scalars
        return _clean(value.item())
    return value
