"""Which keystroke line each MIDI press of an old log belongs to.

The study's scripts pressed a key, then called `pygame.midi.Input.read(R)` (R = 2) and printed
what it returned on the keystroke's line. The MIDI input is a FIFO: a keystroke that makes more
than R events (a double strike, a second note-off) leaves the rest for later lines, and from
then on each line may print the previous keystroke's events (a *backlog*). What the log proves:

1. Events are read in time order, so a press read on line r happened during keystroke r or an
   earlier one.
2. A line that printed fewer than R events emptied the buffer (a *drain*): every press read
   after it belongs to a later keystroke. So a press read on line r can only belong to lines
   after the last drain before r, and presses keep their order (`_bands`).
3. Where that still leaves a choice (a run of full reads), the timestamps decide. Each line's
   cycle is predicted from its control values (`keystroke_timing`) plus one per-session constant
   (the read, the print, sleeps), estimated by profile likelihood: the constant under which the
   best assignment fits the timestamps best. Two presses k' < k are expected
   Σ_{k'≤j<k}(motion_j + constant) apart, give or take their note-on windows; the misfit is
   scored in standard deviations (quadratic; beyond 3 SD a gap that is too *long* grows only
   linearly, because the robot may have paused, while a gap that is too short stays quadratic).
4. A press moves off its read line only when that fits better by more than `BACKLOG_COST` per
   line of backlog it opens (so ties keep the log as written), and where lines carry notes
   (sequence logs) a note that differs from the line's costs `NOTE_COST`; a press whose note
   matches no line it could belong to is left unassigned (a keystroke the log never wrote, e.g.
   one interrupted by a connection drop).

The best assignment is found by dynamic programming over each press's candidate lines (at most
`MAX_BACKLOG_LINES` + 1 of them), cut at presses the structure pins to one line, so time and
memory grow as O(n·w) with w the width of the widest ambiguous stretch. Forward and backward
costs give each press its margin: how much worse the best assignment that puts it elsewhere is.
A margin below `UNDECIDED_MARGIN` means the evidence cannot decide between two lines.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from pianobot.io.keystroke_timing import LineTiming

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

MAX_BACKLOG_LINES = 64  # deepest backlog considered (lines between a press's keystroke and its read)
BACKLOG_COST = 3.0  # prior cost of each line of backlog a press opens (squared SDs)
NOTE_COST = 40.0  # a press whose note differs from its line's key
SIGMA_ABS_S = 0.2  # timing spread of any gap: MIDI latency, scheduling, the read and the print
SIGMA_REL = 0.05  # relative spread of each predicted cycle (moveL blending, controller timing)
SIGMA_REL_UNKNOWN = 0.3  # relative spread of a line whose motion the log does not give
PAUSE_Z = 3.0  # beyond this many SDs, a too-long gap is scored as a pause (linear cost)
PAUSE_SLOPE = 6.0
UNDECIDED_MARGIN = 2.0  # best alternative within this cost: the evidence cannot decide
PROFILE_PRESSES = 4000  # presses used to estimate a session's constant (the first ones)
_INF = np.float64(np.inf)


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
    own_line_cost: FloatArray  # per press: extra cost of keeping it on its read line (inf: impossible)
    unassigned_reason: dict[int, str] = field(default_factory=dict)
    overhead_s: float = 0.0  # the per-line constant on top of the predicted motion
    sigma_scale: float = 1.0  # timing spreads were scaled by this to fit the data
    at_cap: BoolArray = field(default_factory=lambda: np.zeros(0, dtype=bool))


def assign_session(presses: Presses, lines: Lines) -> SessionAssignment:
    """The most plausible line of every press of one session (module docstring)."""
    m = len(presses)
    empty = SessionAssignment(np.full(m, -1, dtype=np.int64), np.full(m, np.inf),
                              np.full(m, -1, dtype=np.int64), np.full(m, np.inf))  # fmt: skip
    if m == 0 or len(lines) == 0:
        empty.at_cap = np.zeros(m, dtype=bool)
        return empty
    keep, reasons = _assignable(presses, lines)
    index = np.flatnonzero(keep)
    sub = Presses(presses.t_s[index], presses.has_on[index], presses.read_line[index], presses.note[index])
    model = _Model(sub, lines)
    if not len(sub):
        empty.unassigned_reason, empty.at_cap = reasons, np.zeros(m, dtype=bool)
        return empty
    model.overhead_s = _profile_overhead(model)
    keys, margin, own, alt = model.solve()
    scale = _misfit_scale(model, keys)
    if scale > 1.5:  # the timestamps scatter more than the defaults allow: trust them less
        model.sigma_scale = scale
        keys, margin, own, alt = model.solve()
    out = empty
    out.line[index], out.margin[index] = keys, margin
    out.own_line_cost[index], out.alternative[index] = own, alt
    out.unassigned_reason = reasons
    out.overhead_s, out.sigma_scale = model.overhead_s, model.sigma_scale
    out.at_cap = np.zeros(m, dtype=bool)
    out.at_cap[index] = model.capped & (keys == model.lo)
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
        first = max(int(lo[i]), taken + 1, r - MAX_BACKLOG_LINES)
        if first > r:
            keep[i] = False
            reasons[i] = "more presses than keystrokes: every line it could belong to holds an earlier press"
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


class _Model:
    """Costs and the dynamic programme of one session (see the module docstring)."""

    def __init__(self, presses: Presses, lines: Lines) -> None:
        self.p = presses
        self.lines = lines
        timing = lines.timing
        motion = timing.motion_s
        self.c1 = np.concatenate([[0.0], np.cumsum(motion)])
        self.c2 = np.concatenate([[0.0], np.cumsum(motion * motion)])
        self.unknown = np.concatenate([[0.0], np.cumsum(~timing.known)])
        self.early, self.late, self.motion = timing.on_early_s, timing.on_late_s, motion
        self.overhead_s = 0.0
        self.sigma_scale = 1.0
        r = presses.read_line
        lo = _after_drain(lines)[r]
        packed = np.maximum.accumulate(lo - np.arange(len(r))) + np.arange(len(r))
        self.capped = packed < r - MAX_BACKLOG_LINES
        self.lo = np.maximum(packed, r - MAX_BACKLOG_LINES)  # first candidate line of each press
        self.r = r

    # --- costs -------------------------------------------------------------------------------
    def window(self, i: int, k: IntArray, o: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Earliest/latest time of press i after the start of line k."""
        if self.p.has_on[i]:
            return self.early[k], self.late[k] + 0.0 * o
        return self.early[k], self.motion[k] + o  # a lone note-off: any time in the cycle

    def pair(self, i: int, kp: IntArray, k: IntArray, o: FloatArray) -> FloatArray:
        """Timing cost of press i-1 on line kp and press i on line k (arrays broadcast)."""
        n = k - kp
        c1, c2 = self.c1[k] - self.c1[kp], self.c2[k] - self.c2[kp]
        unknown = self.unknown[k] - self.unknown[kp]
        span = c1 + n * o
        early_i, late_i = self.window(i, k, o)
        early_p, late_p = self.window(i - 1, kp, o)
        low, high = span + early_i - late_p, span + late_i - early_p
        var = (SIGMA_ABS_S**2 + SIGMA_REL**2 * (c2 + 2 * o * c1 + n * o * o)
               + (SIGMA_REL_UNKNOWN**2 - SIGMA_REL**2) * unknown * o * o)  # fmt: skip
        sd = np.sqrt(np.maximum(var, SIGMA_ABS_S**2)) * self.sigma_scale
        dt = self.p.t_s[i] - self.p.t_s[i - 1]
        z = (dt - np.clip(dt, low, high)) / sd
        cost = np.where(z > PAUSE_Z, PAUSE_Z**2 + PAUSE_SLOPE * (z - PAUSE_Z), z * z)
        return np.where(n > 0, cost, _INF)

    def node(self, i: int, k: IntArray) -> FloatArray:
        """Cost of press i on line k that does not depend on its neighbours (note match)."""
        note, line_note = int(self.p.note[i]), self.lines.note[k]
        if note < 0:
            return np.zeros(k.shape)
        return np.where((line_note >= 0) & (line_note != note), NOTE_COST, 0.0)

    def backlog(self, i: int, kp: IntArray, k: IntArray) -> FloatArray:
        """Prior cost of the backlog lines press i opens beyond press i-1's."""
        grow = (self.r[i] - k) - (self.r[i - 1] - kp)
        return BACKLOG_COST * np.maximum(grow, 0)

    def band(self, i: int) -> IntArray:
        return np.arange(self.lo[i], self.r[i] + 1)

    # --- dynamic programme -------------------------------------------------------------------
    def forward_total(self, overheads: FloatArray) -> FloatArray:
        """Cost of the best assignment for each overhead value (vectorised over them)."""
        o = overheads[:, None, None]
        n = min(len(self.p), PROFILE_PRESSES)
        k0 = self.band(0)
        cost = (BACKLOG_COST * (self.r[0] - k0) + self.node(0, k0))[None, :] + 0.0 * overheads[:, None]
        for i in range(1, n):
            kp, k = self.band(i - 1), self.band(i)
            step = self.pair(i, kp[None, :], k[:, None], o) + self.backlog(i, kp[None, :], k[:, None])
            cost = (cost[:, None, :] + step).min(axis=2) + self.node(i, k)[None, :]
        return cost.min(axis=1)

    def solve(self) -> tuple[IntArray, FloatArray, FloatArray, IntArray]:
        """Best line per press, its margin, the cost of its own line, and the best alternative."""
        m = len(self.p)
        keys = self.r.copy()  # a pinned press has one candidate: its read line
        margin, own = np.full(m, math.inf), np.zeros(m)
        alt = np.full(m, -1, dtype=np.int64)
        pinned = self.lo == self.r
        a = 0
        while a < m:
            if pinned[a]:
                a += 1
                continue
            b = a
            while b < m and not pinned[b]:
                b += 1
            stop = min(b + 1, m)  # the pinned press that ends the stretch is scored with it
            self._solve_stretch(a, stop, keys, margin, own, alt)
            a = stop
        return keys, margin, own, alt

    def _solve_stretch(
        self, a: int, b: int, keys: IntArray, margin: FloatArray, own: FloatArray, alt: IntArray
    ) -> None:
        """Forward/backward over presses a..b-1 (press a-1, if any, is already placed)."""
        o = np.array(self.overhead_s)
        forward: list[FloatArray] = []
        back: list[IntArray] = []
        for i in range(a, b):
            k = self.band(i)
            if i == a:
                if i == 0:
                    f = BACKLOG_COST * (self.r[0] - k) + self.node(0, k)
                else:
                    kp = np.array([keys[i - 1]])
                    f = (self.pair(i, kp[None, :], k[:, None], o)
                         + self.backlog(i, kp[None, :], k[:, None]))[:, 0] + self.node(i, k)  # fmt: skip
                forward.append(f)
                back.append(np.zeros(k.size, dtype=np.int64))
                continue
            kp = self.band(i - 1)
            total = forward[-1][None, :] + self.pair(i, kp[None, :], k[:, None], o) \
                + self.backlog(i, kp[None, :], k[:, None])
            forward.append(total.min(axis=1) + self.node(i, k))
            back.append(total.argmin(axis=1))
        # backward costs (cost of the best continuation from each candidate)
        backward: list[FloatArray] = [np.zeros(forward[-1].size)]
        for i in range(b - 1, a, -1):
            k, kp = self.band(i), self.band(i - 1)
            step = (self.pair(i, kp[None, :], k[:, None], o) + self.backlog(i, kp[None, :], k[:, None])
                    + (self.node(i, k) + backward[0])[:, None])  # fmt: skip
            backward.insert(0, step.min(axis=0))
        x = int(np.argmin(forward[-1]))
        chosen = [x]
        for i in range(b - 1, a, -1):
            x = int(back[i - a][x])
            chosen.append(x)
        chosen.reverse()
        for j, i in enumerate(range(a, b)):
            total = forward[j] + backward[j]
            best = int(chosen[j])
            k = self.band(i)
            keys[i] = k[best]
            others = np.delete(total, best)
            if others.size:
                margin[i] = float(others.min() - total[best])
                alt[i] = int(np.delete(k, best)[int(others.argmin())])
            else:
                margin[i] = math.inf
            own[i] = float(total[-1] - total[best])  # the band ends at the read line


def _profile_overhead(model: _Model) -> float:
    """The per-line constant under which the best assignment fits the timestamps best."""
    p = model.p
    gaps = np.diff(p.t_s)
    steps = np.maximum(np.diff(p.read_line), 1)
    motion = np.diff(model.c1[p.read_line])
    per_line = (gaps - motion) / steps
    typical = float(np.median(per_line)) if per_line.size else 1.0
    top = max(3.0, 3.0 * max(typical, 0.0), float(np.median(gaps)) if gaps.size else 0.0)
    grid = top * np.linspace(0.0, 1.0, 49) ** 1.5
    costs = model.forward_total(grid)
    best = int(np.argmin(costs))
    low, high = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]
    fine = np.linspace(low, high, 17)
    fine_costs = model.forward_total(fine)
    ties = np.flatnonzero(fine_costs <= fine_costs.min() + 1e-9)
    return float(np.median(fine[ties]))


def _misfit_scale(model: _Model, keys: IntArray) -> float:
    """Robust SD of the timing misfits of neighbouring keystrokes (1 = as the model expects)."""
    o = np.array(model.overhead_s)
    z = []
    for i in range(1, len(model.p)):
        if keys[i] - keys[i - 1] == 1 and model.p.has_on[i] and model.p.has_on[i - 1]:
            cost = float(model.pair(i, np.array(keys[i - 1]), np.array(keys[i]), o))
            z.append(math.sqrt(cost) if cost <= PAUSE_Z**2 else PAUSE_Z)
    if len(z) < 8:
        return 1.0
    return float(np.sqrt(np.mean(np.square(z))))
