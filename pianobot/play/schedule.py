"""Fitting one finger's presses into a song's timing: strokes, holds, re-strikes, skips.

Going through the notes in order, each note starts at its onset minus the lead of its stroke,
once the previous played note lets the arm go:

    free = previous start + busy (arm back up + recovery) + hold + move + vacuum change
    free = max(free, previous start + predicted note-off + re-strike margin)   (same key only)

The lateral move starts when the arm is back up, while the released key is still returning (it
rings on its own); only a re-strike of the same key must wait for it to rise past its re-trigger
depth, which is where the piano sends the note-off.

Per note the scheduler takes the stroke closest to the target loudness that (a) starts on time
with the previous note's hold cut as far as needed and (b) still lets the next note start on
time with its fastest stroke within the loudness tolerance (one note of look-ahead). Then it
gives the previous note the longest hold that keeps this start. Because the start of a note
depends only on its own stroke, (b) carries the whole song: whenever every pair of neighbours
fits at their fastest strokes (`need_s`), every note starts on time, so the tempo limit of
`tempo` is exact. At a tempo the user asked for, a note that does not fit starts late by up to
`max_late_s`, then is played louder than the tolerance, and only then skipped and reported.

Everything is arrays and one linear pass of float arithmetic: planning costs microseconds per
note.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pianobot.play.settings import PlaySettings
from pianobot.play.strokes import FloatArray, StrokeTable

CANDIDATES = 8  # strokes tried per note between the aimed one and the fastest within tolerance
EPS_S = 1e-9

# Status codes of `Scheduled.flags` (bit flags; a note may carry several).
ON_TIME, FASTER, LATE, LOUDER, SKIPPED = 0, 1, 2, 4, 8


@dataclass(frozen=True)
class NoteTimes:
    """What the scheduler needs of each note, at the tempo it is played (arrays of length n)."""

    onset_s: FloatArray
    wanted_hold_s: FloatArray  # the note's length as arm hold (from the table's hold map)
    pitch: npt.NDArray[np.int64]
    level: FloatArray  # vacuum level (a key of `tables`)
    aim_mps: FloatArray  # the stroke whose predicted loudness is the target
    fast_mps: FloatArray  # the fastest stroke within the loudness tolerance


@dataclass(frozen=True)
class Scheduled:
    """The scheduler's choices per note."""

    speed_mps: FloatArray
    hold_s: FloatArray
    start_s: FloatArray
    late_s: FloatArray
    move_s: FloatArray  # lateral move from the previous played note
    vacuum_change_s: FloatArray
    flags: npt.NDArray[np.int64]


class _Candidates:
    """Per-note candidate strokes and their timing terms: n × k arrays, and the same as flat
    lists (row-major) for the scheduler's scalar loop — flat, because millions of small nested
    lists would keep the garbage collector busy for longer than the whole plan takes."""

    def __init__(self, speeds: FloatArray, level: FloatArray, tables: dict[float, StrokeTable]) -> None:
        shape = speeds.shape
        self.k = shape[1]
        lead, busy, hold0, slope = (np.full(shape, np.nan) for _ in range(4))
        for key, table in tables.items():
            rows = level == key
            if rows.any():
                s = speeds[rows]
                lead[rows], busy[rows] = table.lead(s), table.busy0(s)
                hold0[rows], slope[rows] = table.hold0(s), table.slope(s)
        self.arrays = {"lead": lead, "busy": busy, "hold0": hold0}
        self.lead: list[float] = lead.ravel().tolist()
        self.busy: list[float] = busy.ravel().tolist()
        self.hold0: list[float] = hold0.ravel().tolist()
        self.slope: list[float] = slope.ravel().tolist()
        self.speeds: list[float] = speeds.ravel().tolist()


def _grid(lo: FloatArray, hi: FloatArray, k: int) -> FloatArray:
    hi = np.maximum(hi, lo)
    return np.asarray(lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, k)[None, :], dtype=np.float64)


def need_s(notes: NoteTimes, tables: dict[float, StrokeTable], settings: PlaySettings,
           gap_s: FloatArray) -> FloatArray:
    """Per note the least onset gap after the previous note, both at their fastest strokes.

    `gap_s[i]` is the move (and vacuum change) between notes i−1 and i. Element 0 is 0.
    """
    c = _Candidates(notes.fast_mps[:, None], notes.level, tables)
    lead, busy, hold0 = (c.arrays[name][:, 0] for name in ("lead", "busy", "hold0"))
    out = np.zeros(lead.size)
    if lead.size > 1:
        after = busy[:-1] - lead[:-1] + gap_s[1:] + lead[1:]
        same = notes.pitch[1:] == notes.pitch[:-1]
        restrike = hold0[:-1] + settings.restrike_margin_s + lead[1:]
        out[1:] = np.where(same, np.maximum(after, restrike), after)
    return out


def schedule(notes: NoteTimes, tables: dict[float, StrokeTable], settings: PlaySettings,
             move_s: Callable[[int, int], float], vacuum_change_s: float, *, allow_skip: bool = True,
             max_late_s: float | None = None, caps_mps: dict[float, float] | None = None) -> Scheduled:
    """One pass over the notes (see the module doc). `move_s(a, b)`: lateral move between keys.

    `allow_skip=False` plays every note, however late (the naive baseline has no tables and
    does not use this function). `caps_mps` per level: the fastest stroke for "louder than the
    tolerance" (default: each table's fastest speed).
    """
    n = notes.onset_s.size
    late_limit = settings.max_late_s if max_late_s is None else max_late_s
    margin = settings.restrike_margin_s
    near = _Candidates(_grid(notes.aim_mps, notes.fast_mps, CANDIDATES), notes.level, tables)
    caps = np.array([(caps_mps or {}).get(float(k), float(tables[float(k)].speeds_mps[-1])) for k in notes.level])
    loud = _Candidates(_grid(notes.fast_mps, caps, CANDIDATES), notes.level, tables)
    K = CANDIDATES
    onset, pitch, level = notes.onset_s.tolist(), notes.pitch.tolist(), notes.level.tolist()
    wanted = notes.wanted_hold_s.tolist()
    speed, hold, start, late = [np.nan] * n, [0.0] * n, [np.nan] * n, [0.0] * n
    moves, vacuum, flags = [0.0] * n, [0.0] * n, [ON_TIME] * n
    chosen: list[tuple[_Candidates, int] | None] = [None] * n

    def between(a: int, b: int) -> tuple[float, float]:
        mv = 0.0 if pitch[a] == pitch[b] else move_s(pitch[a], pitch[b])
        return mv, (vacuum_change_s if level[a] != level[b] else 0.0)

    def ends(c: _Candidates, i: int, k: int, s: float, h: float, to: int) -> float:
        """When the arm may start note `to` after note i played with candidate k from s, hold h."""
        mv, vac = between(i, to)
        free = s + c.busy[i * K + k] + h + mv + vac
        if pitch[i] == pitch[to]:
            free = max(free, s + c.lead[i * K + k] + c.hold0[i * K + k] + c.slope[i * K + k] * h + margin)
        return free

    prev: int | None = None
    for i in range(n):
        if prev is None:
            pc, pk, ps, free0 = near, 0, -np.inf, -np.inf
        else:
            pc, pk = chosen[prev]  # type: ignore[misc]
            ps = start[prev]
            free0 = ends(pc, prev, pk, ps, 0.0, i)
        nxt = i + 1 if i + 1 < n else None
        deadline = onset[nxt] - near.lead[nxt * K + K - 1] if nxt is not None else np.inf
        pick: tuple[_Candidates, int, float, int] | None = None  # (candidates, k, start, flags)
        fallback: tuple[_Candidates, int, float, int] | None = None
        for k in range(CANDIDATES):
            s = onset[i] - near.lead[i * K + k]
            if s < free0 - EPS_S:
                continue
            f = FASTER if k else ON_TIME
            if nxt is None or ends(near, i, k, s, 0.0, nxt) <= deadline + EPS_S:
                pick = (near, k, s, f)
                break
            fallback = (near, k, s, f)  # on time but crowding the next note: the fastest such
        pick = pick or fallback
        if pick is None:
            k = CANDIDATES - 1
            lateness = free0 - (onset[i] - near.lead[i * K + k])
            if lateness <= late_limit + EPS_S:
                pick = (near, k, free0, LATE | (FASTER if k else ON_TIME))
            else:
                for k in range(CANDIDATES):
                    s = onset[i] - loud.lead[i * K + k]
                    if s >= free0 - late_limit - EPS_S:
                        pick = (loud, k, max(s, free0), LOUDER | (LATE if s < free0 - EPS_S else ON_TIME))
                        break
        if pick is None and allow_skip:
            flags[i] = SKIPPED
            continue
        if pick is None:  # play it as soon as the arm is free, however late
            pick = (loud, CANDIDATES - 1, free0, LOUDER | LATE)
        c, k, s, f = pick
        speed[i], start[i], flags[i], chosen[i] = c.speeds[i * K + k], s, f, (c, k)
        late[i] = max(0.0, s - (onset[i] - c.lead[i * K + k]))
        hold[i] = wanted[i]
        if prev is None:
            prev = i
            continue
        moves[i], vacuum[i] = between(prev, i)
        # The previous note keeps the longest hold (up to its length) that still frees the arm by s.
        room = s - ps - pc.busy[prev * K + pk] - moves[i] - vacuum[i]
        if pitch[prev] == pitch[i]:
            room = min(room, (s - ps - pc.lead[prev * K + pk] - pc.hold0[prev * K + pk] - margin) / pc.slope[prev * K + pk])
        hold[prev] = min(hold[prev], max(0.0, room))
        prev = i
    return Scheduled(np.asarray(speed), np.asarray(hold), np.asarray(start), np.asarray(late),
                     np.asarray(moves), np.asarray(vacuum), np.asarray(flags, dtype=np.int64))
