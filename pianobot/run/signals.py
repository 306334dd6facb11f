"""Ctrl-C and SIGTERM while a run is going: finish the trial first, stop at once the second time.

A keystroke interrupted half-way leaves the key pressed and the arm low, so the first signal
only asks the runner to stop after the current trial. A second signal raises KeyboardInterrupt
where the runner is; `open_rig`'s exit still retracts the arm and vents the vacuum, and the
unfinished trial is redone on resume. Further signals during that cleanup are ignored, so an
impatient third Ctrl-C cannot cut the safe shutdown short.
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Callable
from types import FrameType, TracebackType
from typing import Any

HANDLED = (signal.SIGINT, signal.SIGTERM)


class StopControl:
    """A stop request shared by the runner and the signal handlers (or a test)."""

    def __init__(self, notify: Callable[[str], None] | None = None) -> None:
        self.requested: str | None = None  # why a stop after this trial was asked for
        self.immediate = False
        self.shutting_down = False
        self._notify = notify or (lambda message: print(message, file=sys.stderr, flush=True))

    def request(self, reason: str) -> None:
        """Stop after the current trial (idempotent)."""
        if self.requested is None:
            self.requested = reason

    def on_signal(self, signum: int) -> None:
        """First signal: stop after this trial. Second: KeyboardInterrupt now. Then: ignore."""
        name = signal.Signals(signum).name
        if self.shutting_down:
            return
        if self.requested is None:
            self.requested = f"{name}: stopped after the current trial"
            self._notify(f"{name}: finishing the current trial, then stopping (again to stop now)")
            return
        self.immediate = True
        self.shutting_down = True
        self.requested = f"{name} twice: stopped at once, rig made safe"
        raise KeyboardInterrupt(self.requested)


class SignalHandlers:
    """Context manager installing `StopControl.on_signal` for SIGINT and SIGTERM.

    Only the main thread can own signal handlers; elsewhere (a test thread) this does nothing.
    """

    def __init__(self, control: StopControl) -> None:
        self.control = control
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> StopControl:
        if threading.current_thread() is threading.main_thread():
            for signum in HANDLED:
                self._previous[signum] = signal.signal(signum, self._handle)
        return self.control

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        self.control.on_signal(signum)

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        self._previous.clear()
