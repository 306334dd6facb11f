"""Errors that mean "the user's input is wrong": the CLI prints them on one line and exits 2."""

from __future__ import annotations


class InputError(Exception):
    """Bad user input (a spec, a file, an argument).

    `where` names the place: a file and line, a YAML path (`sweep.params.depth_m[2]`), an option.
    """

    def __init__(self, message: str, where: str | None = None) -> None:
        self.message = message
        self.where = where
        super().__init__(f"{where}: {message}" if where else message)
