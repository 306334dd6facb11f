"""How independent pieces of a fit are run: an ordered map over them.

Discovery's candidate fits and identification's bootstrap refits are independent of each other;
they are handed to a `Mapper`, which yields each piece's result in the order of the pieces. The
default `serial_map` runs them one after the other here; `pianobot.executor.Executor.imap` runs
them on a Dask cluster without changing a result: every piece carries its own inputs and seeds.
The caller advances its progress as results come back, so no progress object travels to a worker.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from typing import Protocol, TypeVar

T = TypeVar("T")
R = TypeVar("R")


class Mapper(Protocol):
    """`mapper(function, items)` yields `function(item)` for each item, in order."""

    def __call__(self, function: Callable[[T], R], items: Iterable[T], /) -> Iterator[R]: ...


def serial_map(function: Callable[[T], R], items: Iterable[T], /) -> Iterator[R]:
    """The default mapper: one piece after the other, in this process."""
    for item in items:
        yield function(item)
