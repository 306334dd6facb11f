"""MidiKeyboard through a real JACK server: a separate process plays a scripted piano part."""

from __future__ import annotations

import json
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from typing import Any

import pytest

from pianobot.rig.errors import DeviceUnavailable
from pianobot.rig.midi import MidiKeyboard, resolve_port, to_event

# (offset s, message) — velocity-0 note-ons, a double note-on, active sensing and clock included.
SCRIPT: list[tuple[float, dict[str, Any]]] = [
    (0.00, {"type": "note_on", "note": 57, "velocity": 64}),
    (0.03, {"type": "active_sensing"}),
    (0.12, {"type": "note_on", "note": 57, "velocity": 0}),
    (0.20, {"type": "clock"}),
    (0.25, {"type": "note_on", "note": 59, "velocity": 100}),
    (0.27, {"type": "note_on", "note": 59, "velocity": 30}),
    (0.33, {"type": "active_sensing"}),
    (0.40, {"type": "note_off", "note": 59, "velocity": 45}),
    (0.52, {"type": "note_on", "note": 60, "velocity": 1}),
    (0.53, {"type": "note_on", "note": 60, "velocity": 0}),
    (0.70, {"type": "note_on", "note": 62, "velocity": 127}),
    (0.70, {"type": "note_on", "note": 64, "velocity": 90}),
    (0.85, {"type": "note_off", "note": 62, "velocity": 0}),
    (0.86, {"type": "note_on", "note": 64, "velocity": 0}),
]
NOTE_TYPES = ("note_on", "note_off")

PLAYER = r"""
import json, sys, time
import mido
script = json.loads(sys.argv[2])
backend = mido.Backend("mido.backends.rtmidi/UNIX_JACK", load=True)
port = backend.open_output("keys", client_name=sys.argv[1])
print("READY", flush=True)
sys.stdin.readline()  # the test connects its input, then says go
start = time.monotonic() + 0.05
sent = []
for offset, fields in script:
    while (left := start + offset - time.monotonic()) > 0:
        time.sleep(min(left, 0.0005) if left < 0.002 else left - 0.0015)
    message = mido.Message(**fields)
    sent.append(time.monotonic())
    port.send(message)
time.sleep(0.1)
print(json.dumps(sent), flush=True)
sys.stdin.readline()
port.close()
"""


class MonotonicTestClock:
    """Process-wide CLOCK_MONOTONIC: comparable with the player process's own time.monotonic()."""

    def now(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        time.sleep(seconds)


@pytest.fixture()
def player(jack_server: str) -> Iterator[tuple[subprocess.Popen[str], str]]:
    """A scripted piano in another process with a JACK MIDI output `<client>:keys`."""
    client = f"scripted-piano-{uuid.uuid4().hex[:6]}"
    process = subprocess.Popen(
        [sys.executable, "-c", PLAYER, client, json.dumps(SCRIPT)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
    )
    assert process.stdout is not None
    ready = process.stdout.readline().strip()
    if ready != "READY":
        process.kill()
        pytest.fail(f"player did not start (said {ready!r}, exit {process.poll()})")
    try:
        yield process, client
    finally:
        if process.poll() is None:
            process.kill()
        process.wait()


def _play(process: subprocess.Popen[str]) -> list[float]:
    assert process.stdin is not None and process.stdout is not None
    process.stdin.write("go\n")
    process.stdin.flush()
    sent: list[float] = json.loads(process.stdout.readline())
    process.stdin.write("done\n")
    process.stdin.flush()
    return sent


@pytest.mark.jack
def test_records_every_note_with_script_timing(
    player: tuple[subprocess.Popen[str], str],
) -> None:
    process, client = player
    keyboard = MidiKeyboard(client, api="JACK", clock=MonotonicTestClock())
    keyboard.start()
    try:
        assert keyboard.describe()["port"] == f"{client}:keys"
        sent = _play(process)
        time.sleep(0.05)  # let the last period be delivered
        events = keyboard.events_between(-1e9, 1e9)
    finally:
        keyboard.close()

    expected = [
        (t, fields) for t, (_, fields) in zip(sent, SCRIPT, strict=True)
        if fields["type"] in NOTE_TYPES
    ]
    assert len(events) == len(expected)
    for event, (_, fields) in zip(events, expected, strict=True):
        assert event.note == fields["note"]
        if fields["velocity"] == 0:
            assert (event.type, event.velocity) == ("note_off", 0)
        else:
            assert (event.type, event.velocity) == (fields["type"], fields["velocity"])

    # Relative timing: every interval matches the script's to within 10 ms.
    t0_recorded, t0_sent = events[0].t_s, expected[0][0]
    errors_s = [
        (event.t_s - t0_recorded) - (t_sent - t0_sent)
        for event, (t_sent, _) in zip(events, expected, strict=True)
    ]
    assert max(abs(e) for e in errors_s) < 0.010, errors_s
    # Both processes read the same monotonic clock: an event is stamped after it was sent.
    latencies_s = [event.t_s - t for event, (t, _) in zip(events, expected, strict=True)]
    assert min(latencies_s) > -0.001, latencies_s
    # The clock message reached the callback and was dropped (rtmidi already filters active sensing).
    assert keyboard.ignored_messages >= 1


@pytest.mark.jack
def test_events_are_assigned_by_time_window(player: tuple[subprocess.Popen[str], str]) -> None:
    process, client = player
    keyboard = MidiKeyboard(f"^{client}:", api="JACK", clock=MonotonicTestClock())
    keyboard.start()
    try:
        sent = _play(process)
        time.sleep(0.05)
    finally:
        keyboard.close()
    # The window boundary between the second and third keystroke (offsets 0.25 s and 0.52 s).
    boundary = sent[0] + 0.46
    first = keyboard.events_between(sent[0] - 0.01, boundary)
    second = keyboard.events_between(boundary, sent[-1] + 1.0)
    assert [e.note for e in first] == [57, 57, 59, 59, 59]
    assert [e.note for e in second] == [60, 60, 62, 64, 62, 64]


@pytest.mark.jack
def test_unknown_port_lists_available_ports(jack_server: str) -> None:
    keyboard = MidiKeyboard("no-such-piano", api="JACK", clock=MonotonicTestClock())
    with pytest.raises(DeviceUnavailable, match="no MIDI input port matches 'no-such-piano'"):
        keyboard.start()


def test_resolve_port_prefers_exact_then_pattern() -> None:
    ports = [
        "Kawai ES8:Kawai ES8 MIDI 1 20:0",
        "Midi Through:Midi Through Port-0 14:0",
        "USB Piano [2]:out",
    ]
    assert resolve_port(ports[1], ports) == ports[1]
    assert resolve_port("es8", ports) == ports[0]
    assert resolve_port(r"Through Port-\d", ports) == ports[1]
    assert resolve_port("piano [2", ports) == ports[2]  # not a valid regex: substring
    with pytest.raises(DeviceUnavailable, match="ambiguous"):
        resolve_port("MIDI", ports)


def test_to_event_maps_velocity_zero_and_drops_the_rest() -> None:
    import mido

    on = to_event(mido.Message("note_on", note=60, velocity=0), 1.5)
    assert on is not None and (on.type, on.velocity, on.t_s) == ("note_off", 0, 1.5)
    assert to_event(mido.Message("active_sensing"), 0.0) is None
    assert to_event(mido.Message("clock"), 0.0) is None
    assert to_event(mido.Message("control_change", control=64, value=127), 0.0) is None
