"""The MIDI events of an old keystroke log, grouped into presses.

A *press* is the note events of one physical keystroke: a note-on while no note is held starts
one; further note-ons while a note is held (a double strike: the Kawai sends a second note-on
when the key bounces at the bottom) and the note-offs that release them join it, and so does a
surplus note-off within `REGRIP_GAP_S` of it (a second release message). A note-on after the
key was released always starts a new press, however soon: the next keystroke may follow a late
release closely. A note-on more than `REGRIP_GAP_S` after the press's latest event starts a new
press even if a note-off was lost. A note-off with no press to join is a press of its own (its
note-on was never logged).

Events are arrays (one row per event, in time order within a session) so that logs with hundreds
of thousands of lines group in one pass without an object per event.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

IntArray = npt.NDArray[np.int64]

NOTE_ON = 0x90
NOTE_OFF = 0x80
REGRIP_GAP_S = 1.0  # a held note "re-pressed" after this long means its note-off was lost
KIND_OTHER, KIND_OFF, KIND_ON = 0, 1, 2
KIND_NAMES = {KIND_OTHER: "other", KIND_OFF: "note_off", KIND_ON: "note_on"}


def event_kinds(status: IntArray, velocity: IntArray) -> IntArray:
    """Per event: KIND_ON, KIND_OFF (incl. a note-on with velocity 0) or KIND_OTHER."""
    command = status & 0xF0
    on = (command == NOTE_ON) & (velocity > 0)
    off = (command == NOTE_OFF) | ((command == NOTE_ON) & (velocity == 0))
    return np.where(on, KIND_ON, np.where(off, KIND_OFF, KIND_OTHER)).astype(np.int64)


def group_presses(t_ms: IntArray, kind: IntArray, note: IntArray) -> IntArray:
    """Press number of each event (time order), -1 for events that are not notes."""
    out = np.full(t_ms.size, -1, dtype=np.int64)
    held: dict[int, int] = {}
    current = -1
    last_ms = 0
    regrip_ms = REGRIP_GAP_S * 1000.0
    for j in range(t_ms.size):
        k, t, n = int(kind[j]), int(t_ms[j]), int(note[j])
        if k == KIND_OTHER:
            continue
        gap = t - last_ms
        if k == KIND_ON:
            holding = any(held.values())
            if current < 0 or gap > regrip_ms or not holding:
                current += 1
                held = {}
            held[n] = held.get(n, 0) + 1
        elif current >= 0 and (held.get(n, 0) > 0 or gap <= regrip_ms):
            held[n] = max(0, held.get(n, 0) - 1)
        else:
            current += 1  # an orphan note-off: its note-on was never logged
            held = {n: 0}
        out[j] = current
        last_ms = t
    return out
