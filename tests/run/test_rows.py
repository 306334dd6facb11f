"""A keystroke's MIDI read into its trials row: sounded, silent, or a note-on lost on the way."""

from __future__ import annotations

import math
from types import SimpleNamespace

from pianobot.rig.protocols import KeystrokeResult, MidiEvent, PressRecord
from pianobot.run.rows import read_keystroke


def _row(*events: MidiEvent) -> dict[str, object]:
    trial = SimpleNamespace(trial_id="t1", index=0, note=60)
    result = KeystrokeResult(PressRecord(10.0, 12.0), tuple(events))
    return read_keystroke(trial, 1, result, record=("midi",)).row  # type: ignore[arg-type]


def test_a_note_off_without_its_note_on_is_a_lost_note_not_a_silent_keystroke() -> None:
    heard = _row(MidiEvent(10.30, "note_on", 60, 40), MidiEvent(10.80, "note_off", 60, 0))
    assert heard["status"] == "ok" and heard["on_velocity"] == 40.0 and heard["error"] is None
    assert _row()["status"] == "silent"
    # The note-on dropped on its way (a lossy MIDI link): the key sounded, its loudness unknown.
    # It used to be stored as silent and fed the silence maps; failed, it is left out and redone.
    lost = _row(MidiEvent(10.80, "note_off", 60, 0))
    assert lost["status"] == "failed" and "note-on lost" in str(lost["error"])
    assert math.isnan(float(lost["on_velocity"]))  # type: ignore[arg-type]
    # Another key's note-off says nothing about this one.
    assert _row(MidiEvent(10.80, "note_off", 62, 0))["status"] == "silent"
