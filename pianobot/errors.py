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


#: The largest seed a command takes (numpy's generators take any; 2**63 - 1 fits the run's metadata).
MAX_SEED = 2**63 - 1


def check_seed(seed: int | None, where: str = "--seed") -> None:
    """InputError unless `seed` is None or a whole number from 0 to `MAX_SEED`: checked before
    anything moves or is stored (a negative seed used to fail only inside numpy, mid-run)."""
    if seed is not None and not 0 <= seed <= MAX_SEED:
        raise InputError(f"must be a whole number from 0 to 2**63 - 1, got {seed}", where)
