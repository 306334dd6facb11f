"""How independent pieces of a fit are run: a map over them.

Discovery's candidate fits and identification's bootstrap refits are independent of each other;
they are handed to a `Mapper` (default `serial_map`: one after the other, in order), which a
parallel executor replaces without changing a result: every piece carries its own inputs and
seeds, and results come back in the order of the pieces.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Protocol, TypeVar

T = TypeVar("T")
R = TypeVar("R")


class Mapper(Protocol):
    """`mapper(function, items) -> [function(item) for item in items]`, in order."""

    def __call__(self, function: Callable[[T], R], items: Sequence[T], /) -> list[R]: ...


def serial_map(function: Callable[[T], R], items: Sequence[T], /) -> list[R]:
    """The default mapper: one piece after the other."""
    return [function(item) for item in items]
