"""Re-assigning an old log's MIDI events to keystrokes by timestamp, not by line.

The study's scripts pressed a key, then called `pygame.midi.Input.read(2)` and printed the result
on the keystroke's line. The MIDI buffer is a FIFO that each read drains by at most two events, so
a keystroke that produced more (double note-ons, two note-offs) leaves the rest for the next lines
and a backlog can build up. What the log does tell us:

1. Read order is time order within one MIDI clock; a timestamp that goes backwards (or a header
   line, written when a script starts) begins a new clock *session*.
2. An event read on line r happened during keystroke r or earlier (it was in the buffer).
3. A line with fewer events than the read size drained the buffer: every later event happened
   after it, so it belongs to a later keystroke (a *drain* line).

Rule used here (documented in the module and the run's meta):

- Events are grouped into *presses*: a note-on while no note is held starts a press; further
  note-ons while a note is held (double strikes) and the note-offs that release them join it. A
  note-on more than `REGRIP_GAP_S` after the press's latest event starts a new press even if a
  note-off was lost. A note-off with no open press starts an orphan press.
- Each press i (read first on line r_i) goes to one keystroke k_i with k_i ≤ r_i, k_i after the
  last drain line before r_i, and k strictly increasing. Among those assignments the most
  plausible one is chosen by dynamic programming: each keystroke left silent between presses costs
  `SILENT_COST`, and the gap between consecutive presses should match the cycle times predicted
  from the logged motion (moveL durations + hold) plus a per-session constant (sleeps, approach
  move) estimated robustly from the data. Without backlog the constraints alone decide.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

NOTE_ON = 0x90
NOTE_OFF = 0x80
REGRIP_GAP_S = 1.0  # a held note "re-pressed" after this long means its note-off was lost
SILENT_COST = 2.0  # cost of one silent keystroke, in squared relative-timing errors
TIMING_REL_SD = 0.2  # relative spread of a keystroke cycle around its prediction
TIMING_ABS_SD_S = 0.3  # absolute spread (scheduling jitter, MIDI latency)
MAX_SKIP = 12  # at most this many silent keystrokes between two presses in one step


@dataclass(frozen=True)
class LogEvent:
    """One MIDI event as read from a log line (timestamp in ms on its session's clock)."""

    t_ms: int
    status: int
    note: int
    velocity: int
    record: int  # index of the record (keystroke line) that printed it
    order: int  # position in the file, to keep read order for equal timestamps

    @property
    def kind(self) -> str:
        """The event kind: note_on, note_off (incl. a note-on with velocity 0) or other."""
        command = self.status & 0xF0
        if command == NOTE_ON and self.velocity > 0:
            return "note_on"
        if command in (NOTE_ON, NOTE_OFF):
            return "note_off"
        return "other"


@dataclass(frozen=True)
class Press:
    """The note events of one physical keystroke, in time order."""

    events: tuple[LogEvent, ...]

    @property
    def first_read(self) -> int:
        return min(e.record for e in self.events)

    @property
    def t_s(self) -> float:
        """Time of the first note-on (or of the first event for an orphan note-off)."""
        ons = [e.t_ms for e in self.events if e.kind == "note_on"]
        return (ons[0] if ons else self.events[0].t_ms) / 1000.0


def group_presses(events: Sequence[LogEvent]) -> list[Press]:
    """Group one session's note events (time order) into presses (see module docstring)."""
    presses: list[list[LogEvent]] = []
    held: dict[int, int] = {}
    for event in sorted(events, key=lambda e: (e.t_ms, e.order)):
        kind = event.kind
        if kind == "other":
            continue
        current = presses[-1] if presses else None
        if kind == "note_on":
            stale = current is not None and (event.t_ms - current[-1].t_ms) / 1000.0 > REGRIP_GAP_S
            if current is None or sum(held.values()) == 0 or stale:
                held = {}
                presses.append([event])
            else:
                current.append(event)
            held[event.note] = held.get(event.note, 0) + 1
        elif current is not None and (held.get(event.note, 0) > 0 or _same_release(current, event)):
            current.append(event)
            held[event.note] = max(0, held.get(event.note, 0) - 1)
        else:
            presses.append([event])  # an orphan note-off: its note-on was never logged
    return [Press(tuple(p)) for p in presses]


def _same_release(press: list[LogEvent], event: LogEvent) -> bool:
    """A surplus note-off right after a press's release (within the regrip gap) belongs to it."""
    return (event.t_ms - press[-1].t_ms) / 1000.0 <= REGRIP_GAP_S


def assign_presses(
    presses: Sequence[Press],
    n_records: int,
    drains: Sequence[bool],
    cycle_motion_s: FloatArray,
    down_motion_s: FloatArray,
) -> tuple[list[Press], list[int]]:
    """The presses of one session with the keystroke (line) index each belongs to.

    Args:
        presses: the session's presses in time order; `first_read` is a session-local line index.
        n_records: number of keystroke lines in the session.
        drains: per line, True when it printed fewer events than the read size.
        cycle_motion_s: per line, predicted moveL down + hold + up time (0 where unknown).
        down_motion_s: per line, predicted downward move time (0 where unknown).

    Returns the presses (merged pairwise, closest first, while there are more presses than the
    constraints allow keystrokes) and, for each, its line index; nothing is dropped.
    """
    current = list(presses)
    while current:
        keys = _best_assignment(current, n_records, drains, cycle_motion_s, down_motion_s)
        if keys is not None:
            return current, keys
        gaps = [current[i + 1].t_s - current[i].t_s for i in range(len(current) - 1)]
        if not gaps:  # one press always fits its own line; kept for safety
            return current, [p.first_read for p in current]
        j = int(np.argmin(gaps))
        merged = Press(
            tuple(
                sorted(current[j].events + current[j + 1].events, key=lambda e: (e.t_ms, e.order))
            )
        )
        current[j : j + 2] = [merged]
    return current, []


def _bounds(presses: Sequence[Press], drains: Sequence[bool]) -> tuple[list[int], list[int]]:
    last_drain = []
    latest = -1
    for r, drained in enumerate(drains):
        last_drain.append(latest)  # last drain strictly before line r
        if drained:
            latest = r
    lo = [last_drain[p.first_read] + 1 for p in presses]
    hi = [p.first_read for p in presses]
    return lo, hi


def _best_assignment(
    presses: Sequence[Press],
    n_records: int,
    drains: Sequence[bool],
    cycle_motion_s: FloatArray,
    down_motion_s: FloatArray,
) -> list[int] | None:
    m = len(presses)
    lo, hi = _bounds(presses, drains)
    t = np.array([p.t_s for p in presses])
    constant_s = _cycle_constant(t, lo, hi, cycle_motion_s, down_motion_s)
    cycle = cycle_motion_s + (constant_s if constant_s is not None else 0.0)
    start = np.concatenate([[0.0], np.cumsum(cycle)])  # predicted start time of each line
    k_all = np.arange(n_records)
    inf = math.inf
    cost = np.full(n_records, inf)
    ok = (k_all >= lo[0]) & (k_all <= hi[0])
    cost[ok] = SILENT_COST * (k_all[ok] - lo[0])
    back: list[npt.NDArray[np.int64]] = [np.full(n_records, -1, dtype=np.int64)]
    for i in range(1, m):
        new = np.full(n_records, inf)
        arg = np.full(n_records, -1, dtype=np.int64)
        gap = t[i] - t[i - 1]
        for skip in range(0, min(MAX_SKIP, n_records) + 1):
            step = skip + 1
            k = k_all[step:]
            prev = k - step
            total = cost[prev] + SILENT_COST * skip
            if constant_s is not None:
                expected = start[k] - start[prev] + down_motion_s[k] - down_motion_s[prev]
                z = (gap - expected) / (TIMING_REL_SD * np.abs(expected) + TIMING_ABS_SD_S)
                total = total + z * z
            better = total < new[step:]
            new[step:] = np.where(better, total, new[step:])
            arg[step:] = np.where(better, prev, arg[step:])
        allowed = (k_all >= lo[i]) & (k_all <= hi[i])
        new[~allowed] = inf
        cost = new
        back.append(arg)
    if not np.isfinite(cost).any():
        return None
    keys = [int(np.argmin(cost))]
    for i in range(m - 1, 0, -1):
        keys.append(int(back[i][keys[-1]]))
    keys.reverse()
    return keys


def _cycle_constant(
    t: FloatArray,
    lo: Sequence[int],
    hi: Sequence[int],
    cycle_motion_s: FloatArray,
    down_motion_s: FloatArray,
) -> float | None:
    """The per-keystroke time not explained by the logged motion (sleeps, approach move).

    Estimated as the median, over consecutive presses that the earliest feasible packing puts on
    consecutive lines, of gap − predicted motion. None when there is no such pair.
    """
    keys: list[int] = []
    for i in range(len(t)):
        k = lo[i] if not keys else max(lo[i], keys[-1] + 1)
        keys.append(min(k, hi[i]))
    residuals = [
        (t[i] - t[i - 1])
        - (cycle_motion_s[keys[i - 1]] + down_motion_s[keys[i]] - down_motion_s[keys[i - 1]])
        for i in range(1, len(t))
        if keys[i] - keys[i - 1] == 1
    ]
    if not residuals:
        return None
    return max(0.0, float(np.median(residuals)))
