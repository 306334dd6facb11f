"""Which keystroke line each MIDI press of an old log belongs to.

The study's scripts pressed a key, then called `pygame.midi.Input.read(R)` (R = 2) and printed
what it returned on the keystroke's line. The MIDI input is a FIFO: a keystroke that makes more
than R events (a double strike, a second note-off) leaves the rest for later lines, and from
then on each line may print the previous keystroke's events (a *backlog*). What the log proves:

1. Events are read in time order, so a press read on line r happened during keystroke r or an
   earlier one.
2. A line that printed fewer than R events emptied the buffer (a *drain*): every press read
   after it belongs to a later keystroke. So a press read on line r can only belong to lines
   after the last drain before r, and presses keep their order: each press has a structural
   band of lines, from the earliest the presses before it leave free to its read line (or the
   latest the presses after it leave free). Where the band is one line, nothing can move.
3. Where that still leaves a choice (a run of full reads), the timestamps decide. Each line's
   cycle is predicted from its control values (`keystroke_timing`) plus one per-session constant
   (the read, the print, sleeps), estimated by profile likelihood: the constant under which the
   best assignment fits the timestamps best. Two presses k' < k are expected
   Σ_{k'≤j<k}(motion_j + constant) apart, give or take their note-on windows; the misfit is
   scored in standard deviations (quadratic; beyond 3 SD a gap that is too *long* grows only
   logarithmically, because the robot may have paused for any time, while a gap that is too short
   stays quadratic: no stroke is faster than its motion).
4. A press moves off its read line only when that fits better by more than `BACKLOG_COST` per
   line of backlog it opens (so ties keep the log as written), and where lines carry notes
   (sequence logs) a note that differs from the line's costs `NOTE_COST`; a press whose note
   matches no line it could belong to is left unassigned (a keystroke the log never wrote, e.g.
   one interrupted by a connection drop).

The best assignment is found by dynamic programming (`_assign_kernel`, compiled) over each
press's candidate lines: its band, cut to what the previous press's surviving candidates allow
(a beam), so time and memory grow as O(n·w) with w the number of candidates kept per press (one
for a pinned press); a backlog of any depth is followed. Forward and backward costs give each
press its margin: how much worse the best assignment that puts it elsewhere is. A margin below
`UNDECIDED_MARGIN` means the evidence cannot decide between two lines. The cost constants
(`BACKLOG_COST`, `NOTE_COST`, the timing spreads, the pause tail) are defined, with their
meaning, in `_assign_kernel`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from pianobot.io import _assign_kernel as kernel
from pianobot.io._assign_kernel import PAUSE_Z
from pianobot.io.keystroke_timing import LineTiming

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

NOTE_SEARCH_LINES = 64  # a press whose key no line this far back has belongs to no logged line
UNDECIDED_MARGIN = 2.0  # best alternative within this cost: the evidence cannot decide
PROFILE_PRESSES = 2000  # presses used to estimate a session's constant (the first ones)


@dataclass(frozen=True)
class Presses:
    """One session's presses in time order (times on the session's MIDI clock)."""

    t_s: FloatArray  # first note-on (or first event of a press without one)
    has_on: BoolArray
    read_line: IntArray  # session-local line index where its first event was printed
    note: IntArray  # -1: none

    def __len__(self) -> int:
        return int(self.t_s.size)


@dataclass(frozen=True)
class Lines:
    """One session's keystroke lines."""

    reads: IntArray  # events printed on each line
    read_size: int  # events a read returns at most (R)
    timing: LineTiming
    note: IntArray  # the line's key (-1: not logged)

    def __len__(self) -> int:
        return int(self.reads.size)


@dataclass
class SessionAssignment:
    """Where each press went, and how sure that is."""

    line: IntArray  # per press: its line, -1 when it belongs to no line of the log
    margin: FloatArray  # per press: extra cost of the best assignment that puts it elsewhere
    alternative: IntArray  # per press: the line of that assignment (-1: none)
    own_line_cost: FloatArray  # per press: extra cost of keeping it on its read line (inf: none)
    unassigned_reason: dict[int, str] = field(default_factory=dict)
    overhead_s: float = 0.0  # the per-line constant on top of the predicted motion
    sigma_scale: float = 1.0  # timing spreads were scaled by this to fit the data
    at_cap: BoolArray = field(default_factory=lambda: np.zeros(0, dtype=bool))


def assign_session(presses: Presses, lines: Lines) -> SessionAssignment:
    """The most plausible line of every press of one session (module docstring)."""
    m = len(presses)
    empty = SessionAssignment(
        np.full(m, -1, dtype=np.int64),
        np.full(m, np.inf),
        np.full(m, -1, dtype=np.int64),
        np.full(m, np.inf),
    )
    if m == 0 or len(lines) == 0:
        empty.at_cap = np.zeros(m, dtype=bool)
        return empty
    keep, reasons = _assignable(presses, lines)
    index = np.flatnonzero(keep)
    sub = Presses(
        presses.t_s[index], presses.has_on[index], presses.read_line[index], presses.note[index]
    )
    model = _Model(sub, lines)
    if not len(sub):
        empty.unassigned_reason, empty.at_cap = reasons, np.zeros(m, dtype=bool)
        return empty
    model.overhead_s = _profile_overhead(model)
    keys, margin, own, alt, last = model.solve()
    scale = _misfit_scale(model, keys)
    if scale > 1.5:  # the timestamps scatter more than the defaults allow: trust them less
        model.sigma_scale = scale
        keys, margin, own, alt, last = model.solve()
    out = empty
    out.line[index], out.margin[index] = keys, margin
    out.own_line_cost[index], out.alternative[index] = own, alt
    out.unassigned_reason = reasons
    out.overhead_s, out.sigma_scale = model.overhead_s, model.sigma_scale
    out.at_cap = np.zeros(m, dtype=bool)
    out.at_cap[index] = (keys == last) & (last < model.hi)
    return out


def _assignable(presses: Presses, lines: Lines) -> tuple[BoolArray, dict[int, str]]:
    """Presses that can belong to a line; the others with the reason why not.

    A press whose note matches no line it could belong to, or one more than the lines between
    the last drain and its read line can hold, belongs to no logged keystroke.
    """
    keep = np.ones(len(presses), dtype=bool)
    reasons: dict[int, str] = {}
    lo = _after_drain(lines)[presses.read_line]
    taken = -1  # the earliest line the presses kept so far can occupy
    for i in range(len(presses)):
        r = int(presses.read_line[i])
        first = max(int(lo[i]), taken + 1, r - NOTE_SEARCH_LINES)
        if first > r:
            keep[i] = False
            reasons[i] = (
                "more presses than keystrokes: every line it could belong to holds an earlier press"
            )
            continue
        note = int(presses.note[i])
        candidates = lines.note[first : r + 1]
        if note >= 0 and (candidates >= 0).all() and not (candidates == note).any():
            keep[i] = False
            reasons[i] = f"note:{first}"  # the caller words it with file line numbers
            continue
        taken = first
    return keep, reasons


def _after_drain(lines: Lines) -> IntArray:
    """Per line r: the first line after the last drain before r (0 when none)."""
    drain = lines.reads < lines.read_size
    marks = np.where(drain, np.arange(len(lines)), -1)
    last = np.maximum.accumulate(marks)  # last drain at or before r
    before = np.concatenate([[-1], last[:-1]])  # strictly before r
    return (before + 1).astype(np.int64)


# The compiled kernels (numba dispatchers take any arguments; their signatures are in the kernel).
_BEST_TOTAL: Any = kernel.best_total
_VITERBI: Any = kernel.viterbi
_PAIR_COSTS: Any = kernel.pair_costs


class _Model:
    """The arrays of one session's dynamic programme (costs in `_assign_kernel`)."""

    def __init__(self, presses: Presses, lines: Lines) -> None:
        self.p = presses
        timing = lines.timing
        motion = timing.motion_s.astype(np.float64)
        self.c1 = np.concatenate([[0.0], np.cumsum(motion)])
        self.c2 = np.concatenate([[0.0], np.cumsum(motion * motion)])
        self.unknown = np.concatenate([[0.0], np.cumsum(~timing.known)]).astype(np.float64)
        self.early, self.late, self.motion = timing.on_early_s, timing.on_late_s, motion
        self.line_note = lines.note.astype(np.int64)
        self.overhead_s = 0.0
        self.sigma_scale = 1.0
        r = presses.read_line.astype(np.int64)
        m = np.arange(len(r))
        lo = _after_drain(lines)[r]
        self.lo = (
            np.maximum.accumulate(lo - m) + m
        )  # earliest line: after the drain, after earlier presses
        self.hi = (np.minimum.accumulate((r - m)[::-1])[::-1] + m).astype(
            np.int64
        )  # latest: before later presses
        self.r = r
        drains = np.flatnonzero(lines.reads < lines.read_size)
        self.last_drain = int(drains.max()) if drains.size else -1
        silent_share = min(max(1.0 - len(presses) / len(lines), 0.05), 0.95)
        self.silent_cost = -math.log(silent_share)

    def _presses(self) -> tuple[Any, ...]:
        p = self.p
        return (
            self.lo,
            self.hi,
            self.r,
            p.t_s.astype(np.float64),
            p.has_on.astype(np.bool_),
            p.note.astype(np.int64),
        )

    def _lines(self) -> tuple[Any, ...]:
        return (self.c1, self.c2, self.unknown, self.early, self.late, self.motion)

    def total(self, overhead_s: float, bound: float = math.inf) -> float:
        """Cost of the best assignment of the session's first PROFILE_PRESSES presses (infinite
        once it exceeds `bound`)."""
        m = min(len(self.p), PROFILE_PRESSES)
        whole = m == len(self.p)
        return float(
            _BEST_TOTAL(
                *self._presses(),
                *self._lines(),
                self.line_note,
                overhead_s,
                self.sigma_scale,
                self.silent_cost if whole else 0.0,
                self.last_drain,
                m,
                bound,
            )
        )

    def solve(self) -> tuple[IntArray, FloatArray, FloatArray, IntArray, IntArray]:
        """Best line per press, its margin, the cost of its own line, the best alternative, and
        the last line it was allowed (its window may stop short of its structural band)."""
        found: tuple[IntArray, FloatArray, FloatArray, IntArray, IntArray] = _VITERBI(
            *self._presses(),
            *self._lines(),
            self.line_note,
            self.overhead_s,
            self.sigma_scale,
            self.silent_cost,
            self.last_drain,
        )
        return found

    def pair_costs(self, keys: IntArray) -> FloatArray:
        """Timing cost of each press with its predecessor under an assignment."""
        p = self.p
        costs: FloatArray = _PAIR_COSTS(
            keys,
            self.overhead_s,
            self.sigma_scale,
            p.t_s.astype(np.float64),
            p.has_on.astype(np.bool_),
            *self._lines(),
        )
        return costs


def _profile_overhead(model: _Model) -> float:
    """The per-line constant under which the best assignment fits the timestamps best."""
    p = model.p
    gaps = np.diff(p.t_s)
    steps = np.maximum(np.diff(p.read_line), 1)
    motion = np.diff(model.c1[p.read_line])
    per_line = (gaps - motion) / steps
    typical = float(np.median(per_line)) if per_line.size else 1.0
    top = max(3.0, 3.0 * max(typical, 0.0), float(np.median(gaps)) if gaps.size else 0.0)
    grid = top * np.linspace(0.0, 1.0, 25) ** 1.5
    costs = _costs(model, grid, start=float(np.clip(typical, 0.0, top)))
    best = int(np.argmin(costs))
    fine = np.linspace(grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)], 9)
    fine_costs = _costs(model, fine, start=float(grid[best]))
    ties = np.flatnonzero(fine_costs <= fine_costs.min() + 1e-9)
    return float(np.median(fine[ties]))


def _costs(model: _Model, overheads: FloatArray, start: float) -> FloatArray:
    """Best cost per overhead value; values far off are cut short once they exceed the best so
    far (evaluated from `start` outwards, so the good ones come first)."""
    costs = np.full(overheads.size, math.inf)
    best = math.inf
    for j in np.argsort(np.abs(overheads - start)):
        costs[j] = model.total(float(overheads[j]), bound=best + 1e-6)
        best = min(best, costs[j])
    return costs


def _misfit_scale(model: _Model, keys: IntArray) -> float:
    """Robust SD of the timing misfits of neighbouring keystrokes (1 = as the model expects)."""
    costs = model.pair_costs(keys)[1:]
    both_on = model.p.has_on[1:] & model.p.has_on[:-1]
    adjacent = (np.diff(keys) == 1) & both_on
    z = np.sqrt(np.minimum(costs[adjacent], PAUSE_Z**2))
    if z.size < 8:
        return 1.0
    return float(np.sqrt(np.mean(z * z)))
