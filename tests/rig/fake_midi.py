"""A fake of the mido backend used by MidiKeyboard: fixed port names, messages injected by hand."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import mido


class FakePort:
    def __init__(self, name: str, callback: Callable[[Any], None]) -> None:
        self.name = name
        self.callback = callback
        self.closed = False

    def close(self) -> None:
        self.closed = True


class FakeMidiBackend:
    """`get_input_names` / `open_input(name, callback=...)` like `mido.Backend`."""

    def __init__(self, names: list[str]) -> None:
        self.names = names
        self.ports: list[FakePort] = []

    def get_input_names(self) -> list[str]:
        return list(self.names)

    def open_input(self, name: str, *, callback: Callable[[Any], None]) -> FakePort:
        if name not in self.names:
            raise OSError(f"unknown port {name!r}")
        port = FakePort(name, callback)
        self.ports.append(port)
        return port

    def play(self, kind: str, **fields: Any) -> None:
        """Deliver a message to every open port (the callback stamps it on the run clock)."""
        for port in self.ports:
            if not port.closed:
                port.callback(mido.Message(kind, **fields))
