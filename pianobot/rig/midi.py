"""MIDI input from the piano through mido's python-rtmidi backend (ALSA for the lab, JACK in tests).

Live input from rtmidi carries no usable time in mido (`msg.time` is 0), so every event is stamped
on the run clock inside the callback, the moment it arrives. Events are kept in a thread-safe
buffer and handed out by time window (`events_between`), never by count: the study's logs show
double note-ons and events spilling into the next record when a fixed number of reads per
keystroke was assumed.
"""

from __future__ import annotations

import re
import threading
from collections.abc import Callable, Sequence
from typing import Any, Literal, Protocol

from pianobot.rig.errors import DeviceUnavailable
from pianobot.rig.protocols import Clock, MidiEvent

MidiApi = Literal["ALSA", "JACK", "auto"]

# mido backend names of the python-rtmidi APIs we use.
_BACKENDS: dict[str, str] = {
    "ALSA": "mido.backends.rtmidi/LINUX_ALSA",
    "JACK": "mido.backends.rtmidi/UNIX_JACK",
}
# Buffer bound: a day of dense playing at 10 events/s; older events are dropped first.
MAX_BUFFERED_EVENTS = 1_000_000


class MidiPort(Protocol):
    """The part of a mido input port we use."""

    name: str

    def close(self) -> None: ...


class MidiBackend(Protocol):
    """The part of `mido.Backend` we use (injectable for tests)."""

    def get_input_names(self) -> list[str]: ...

    def open_input(self, name: str, *, callback: Callable[[Any], None]) -> MidiPort: ...


BackendFactory = Callable[[str], MidiBackend]


def mido_backend(api: str) -> MidiBackend:
    """The mido rtmidi backend for one API ("ALSA" or "JACK"), imported lazily."""
    try:
        import mido
        import rtmidi  # noqa: F401  (mido loads it lazily; fail here with a clear message)
    except ImportError as exc:
        raise DeviceUnavailable(
            f"MIDI input needs mido and python-rtmidi (pip install 'pianobot[midi]'): {exc}"
        ) from exc
    backend: MidiBackend = mido.Backend(_BACKENDS[api], load=True)
    return backend


def compiled_apis() -> list[str]:
    """The MIDI APIs this python-rtmidi build supports, as "ALSA"/"JACK" names."""
    try:
        import rtmidi
    except ImportError:
        return []
    names = {rtmidi.API_LINUX_ALSA: "ALSA", rtmidi.API_UNIX_JACK: "JACK"}
    return [names[api] for api in rtmidi.get_compiled_api() if api in names]


def resolve_port(pattern: str, available: Sequence[str]) -> str:
    """Pick the one port matching `pattern`: exact name, else regex search, else substring.

    Raises DeviceUnavailable naming the available ports when nothing or more than one matches.
    """
    if pattern in available:
        return pattern
    try:
        regex = re.compile(pattern, re.IGNORECASE)
        matches = [name for name in available if regex.search(name)]
    except re.error:
        matches = []
    if not matches:
        matches = [name for name in available if pattern.lower() in name.lower()]
    listing = ", ".join(repr(name) for name in available) or "none"
    if not matches:
        raise DeviceUnavailable(f"no MIDI input port matches {pattern!r}; available: {listing}")
    if len(matches) > 1:
        found = ", ".join(repr(name) for name in matches)
        raise DeviceUnavailable(
            f"MIDI port pattern {pattern!r} is ambiguous: matches {found}; use the exact name"
        )
    return matches[0]


def to_event(message: Any, t_s: float) -> MidiEvent | None:
    """A note message as a MidiEvent on the run clock; None for everything else.

    A note_on with velocity 0 is a note-off (running-status pianos send it that way); active
    sensing, clock, controllers and sysex are not keystrokes and are dropped.
    """
    kind = getattr(message, "type", None)
    if kind == "note_on" and message.velocity == 0:
        return MidiEvent(t_s=t_s, type="note_off", note=int(message.note), velocity=0)
    if kind in ("note_on", "note_off"):
        return MidiEvent(t_s=t_s, type=kind, note=int(message.note), velocity=int(message.velocity))
    return None


class MidiKeyboard:
    """The piano's MIDI output, recorded on the run clock (implements the `Keyboard` protocol).

    Args:
        port_pattern: exact port name, a regex or a substring (case-insensitive) of one port.
        api: "ALSA" (the lab's USB piano), "JACK" (tests), or "auto" (first API with a match).
        clock: the run clock; `now()` is called from the MIDI thread, so it must be thread-safe.
        note: record only this note (the rig file's `midi.note`); None records every note.
        backend_factory: builds a mido-like backend for an API name (tests inject fakes).
    """

    def __init__(
        self,
        port_pattern: str,
        api: MidiApi = "ALSA",
        *,
        clock: Clock,
        note: int | None = None,
        backend_factory: BackendFactory = mido_backend,
    ) -> None:
        if api not in ("ALSA", "JACK", "auto"):
            raise DeviceUnavailable(f"MIDI api must be ALSA, JACK or auto, got {api!r}")
        self.port_pattern = port_pattern
        self.api: MidiApi = api
        self._clock = clock
        self.note = note
        self._backend_factory = backend_factory
        self._lock = threading.Lock()
        self._events: list[MidiEvent] = []
        self._port: MidiPort | None = None
        self._api_used: str | None = None
        self.ignored_messages = 0

    def start(self) -> None:
        """Open the matching input port; events are recorded from now on."""
        if self._port is not None:
            return
        apis = [self.api] if self.api != "auto" else (compiled_apis() or ["ALSA", "JACK"])
        errors: list[str] = []
        for api in apis:
            try:
                backend = self._backend_factory(api)
                name = resolve_port(self.port_pattern, backend.get_input_names())
                self._port = backend.open_input(name, callback=self._on_message)
            except DeviceUnavailable as exc:
                errors.append(f"{api}: {exc}")
                continue
            except (OSError, RuntimeError, SystemError) as exc:
                errors.append(f"{api}: cannot open MIDI port {self.port_pattern!r}: {exc}")
                continue
            self._api_used = api
            return
        raise DeviceUnavailable("; ".join(errors))

    def _on_message(self, message: Any) -> None:
        # Stamp first: anything done before reading the clock adds latency to the timestamp.
        t_s = self._clock.now()
        event = to_event(message, t_s)
        if event is not None and self.note is not None and event.note != self.note:
            event = None
        with self._lock:
            if event is None:
                self.ignored_messages += 1
                return
            self._events.append(event)
            if len(self._events) > MAX_BUFFERED_EVENTS:
                del self._events[: len(self._events) - MAX_BUFFERED_EVENTS]

    def events_between(self, t_from_s: float, t_to_s: float) -> list[MidiEvent]:
        """Events with t_from_s <= t_s < t_to_s, in arrival order."""
        with self._lock:
            return [e for e in self._events if t_from_s <= e.t_s < t_to_s]

    def close(self) -> None:
        """Close the port (safe to call twice)."""
        port, self._port = self._port, None
        if port is not None:
            try:
                port.close()
            except (OSError, RuntimeError):
                pass

    def describe(self) -> dict[str, Any]:
        """Port and API, for run metadata."""
        return {
            "kind": "midi",
            "api": self._api_used or self.api,
            "port_pattern": self.port_pattern,
            "note": self.note,
            "port": self._port.name if self._port is not None else None,
        }
