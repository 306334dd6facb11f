"""Keystroke logs written from known truth, the way the study's scripts wrote them.

Shares no code with pianobot (it imports nothing from it): the robot is stepped at 1 ms through
its own speed profiles (with a start latency and a settling time pianobot's timing model does
not know), the key triggers at a depth drawn per stroke, the soft finger lets the key lag the
arm by a drawn ratio, and the MIDI input is a FIFO that each `read(R)` after a stroke drains by
at most R events. What each stroke really produced, and on which line each event was printed,
is kept, so a test can check the importer's assignment event by event.

Scenarios (`Scenario`): layout (the soft sweep, the rigid acceleration sweep, named keys with
notes), how often strokes sound (a probability, or "fast-late": only fast strokes late in the
file), double strikes (on, on, off, off: a backlog of 1–2 events), late releases, pauses,
restarts of the script (the MIDI clock starts again; unread events are lost), and the read size.
"""

from __future__ import annotations

import functools
import random
from dataclasses import dataclass, field

import numpy as np

STEP_S = 0.001
SOFT_NOTE = 57
WHITE = {"C": 60, "D": 62, "E": 64, "F": 65, "G": 67, "A": 69, "B": 71}


@dataclass(frozen=True)
class Scenario:
    n: int = 60
    layout: str = "soft"  # soft | rigid-acc | named
    sound: float | str = 0.7  # probability a stroke sounds, or "fast-late"
    double_strike: float = 0.0
    late_release: float = 0.0  # the note-off comes after the read (key released slowly)
    pause: float = 0.0  # probability of an unlogged pause of 5–40 s before a stroke
    restarts: tuple[int, ...] = ()  # strokes at which the script restarts
    header_on_restart: bool = True
    read_size: int = 2
    seed: int = 0


@dataclass
class Stroke:
    """One keystroke line: what the robot did and what the piano sent."""

    line: int  # file line number
    session: int
    events: list[tuple[str, int, int, int]] = field(
        default_factory=list
    )  # (type, note, velocity, t_ms)
    printed_on: list[int] = field(default_factory=list)  # per event: file line, -1 never read

    @property
    def sounded(self) -> bool:
        return any(kind == "on" for kind, *_ in self.events)

    @property
    def outcome(self) -> str:
        """ok (its first note-on was printed), lost (it sounded, nothing printed), silent."""
        if not self.sounded:
            return "silent"
        first_on = next(i for i, e in enumerate(self.events) if e[0] == "on")
        return "ok" if self.printed_on[first_on] >= 0 else "lost"

    def printed(self) -> set[tuple[str, int, int]]:
        """The events of this stroke that reached the log: (type, t_ms, velocity)."""
        return {
            (k, t, v)
            for (k, _, v, t), line in zip(self.events, self.printed_on, strict=True)
            if line >= 0
        }


@dataclass
class TruthLog:
    text: str
    strokes: list[Stroke]

    def by_line(self) -> dict[int, Stroke]:
        return {s.line: s for s in self.strokes}


@functools.lru_cache(maxsize=4096)  # the sweeps repeat their grid: the same moves over and over
def _move_s(distance: float, speed: float, accel: float) -> np.ndarray:
    """Position (m) every STEP_S along a move: accelerate, cruise, brake (stepped, not closed form)."""
    if distance <= 0:
        return np.zeros(1)
    # speed at each step while accelerating, then the mirror image while braking: step until the
    # distance covered by accelerating + braking reaches the move's length
    ramp = np.minimum(np.arange(1, int(speed / (accel * STEP_S)) + 2) * accel * STEP_S, speed)
    covered = 2 * np.cumsum(ramp) * STEP_S
    if covered[-1] >= distance:  # never cruises
        n = int(np.searchsorted(covered, distance)) + 1
        v = np.concatenate([ramp[:n], ramp[:n][::-1]])
    else:
        cruise = int(np.ceil((distance - covered[-1]) / (speed * STEP_S)))
        v = np.concatenate([ramp, np.full(cruise, speed), ramp[::-1]])
    return np.minimum(np.concatenate([[0.0], np.cumsum(v) * STEP_S]), distance)


def _controls(sc: Scenario, k: int, rng: random.Random) -> dict[str, float | str]:
    if sc.layout == "soft":
        grid = [
            (a, 0.01 + 0.005 * v, d)
            for a in (0.1, 0.5, 1.0)
            for v in range(15)
            for d in (0.02, 0.03, 0.04)
        ]
        acc, vel, depth = grid[k % len(grid)]
        return {"acc": acc, "vel": vel, "depth": depth, "distance": 0.05, "hold": 0.0, "vac": 60}
    if sc.layout == "rigid-acc":
        accs = [4.01 - 0.4 * i for i in range(11)]
        return {
            "acc": accs[(k // 11) % 11],
            "up_acc": accs[k % 11],
            "vel": 0.774,
            "distance": 0.035,
            "hold": 1.0,
            "depth": 0.01,
        }
    note = rng.choice("CDEFGAB")
    return {
        "note": note,
        "move_vel": rng.uniform(0.05, 1.0),
        "move_acc": rng.uniform(0.1, 2.0),
        "down_vel": rng.uniform(0.02, 1.0),
        "up_vel": rng.uniform(0.02, 1.0),
        "acc": rng.uniform(0.1, 2.0),
        "up_acc": rng.uniform(0.1, 2.0),
        "distance": rng.uniform(0.002, 0.08),
        "hold": rng.uniform(0.0, 3.0),
        "depth": rng.uniform(0.008, 0.015),
    }


def _line_text(
    sc: Scenario, c: dict[str, float | str], k: int, printed: list[tuple[int, int, int, int]]
) -> str:
    midi = [[[status, note, vel, 0], t] for status, note, vel, t in printed]
    if sc.layout == "soft":
        control = [c["vac"], 45, c["acc"], c["vel"], c["depth"], c["distance"], c["hold"]]
        return repr({"control": control, "midi": midi})
    if sc.layout == "rigid-acc":
        control = [0, c["acc"], c["up_acc"], c["vel"], c["distance"], c["hold"]]
        return repr({"control": control, "midi": midi})
    return repr(
        {
            "group": k // 12,
            "order": k % 12,
            "note": c["note"],
            "move_vel": c["move_vel"],
            "down_vel": c["down_vel"],
            "up_vel": c["up_vel"],
            "distance": c["distance"],
            "hold_time": c["hold"],
            "move_acc": c["move_acc"],
            "down_acc": c["acc"],
            "up_acc": c["up_acc"],
            "press_depth": c["depth"],
            "midi": midi,
        }
    )


def make_log(sc: Scenario) -> TruthLog:
    """Simulate the lab for `sc.n` strokes and write the log the script would have written."""
    rng = random.Random(sc.seed)
    lines: list[str] = []
    strokes: list[Stroke] = []
    fifo: list[
        tuple[int, int, int, int, Stroke, int]
    ] = []  # t_ms, status, note, vel, stroke, event
    clock = rng.uniform(1.0, 3.0)
    overhead = rng.uniform(0.2, 2.5)
    session = 0
    previous_key = None
    for k in range(sc.n):
        if k in sc.restarts:
            for *_, stroke, j in fifo:
                stroke.printed_on[j] = -1
            fifo.clear()
            clock, overhead, session = rng.uniform(1.0, 3.0), rng.uniform(0.2, 2.5), session + 1
            if sc.header_on_restart:
                lines.append(
                    repr({"start_position_l": [round(rng.uniform(-1, 1), 5) for _ in range(6)]})
                )
        if rng.random() < sc.pause:
            clock += rng.uniform(5.0, 40.0)
        c = _controls(sc, k, rng)
        stroke = Stroke(line=len(lines) + 1, session=session)
        start = clock + rng.uniform(0.008, 0.03)  # controller latency before the move begins
        key = (
            WHITE[str(c["note"])]
            if sc.layout == "named"
            else (60 if sc.layout == "rigid-acc" else SOFT_NOTE)
        )
        if sc.layout == "named" and previous_key is not None:
            sideways = abs(key - previous_key) / 12 * 7 * 0.0235
            start += (
                len(_move_s(sideways, float(c["move_vel"]), float(c["move_acc"]))) * STEP_S
                if sideways
                else 0.0
            )
        previous_key = key
        travel = float(c["distance"]) + float(c["depth"])
        down = _move_s(travel, float(c["vel"] if "vel" in c else c["down_vel"]), float(c["acc"]))
        up_travel = float(c["depth"]) if sc.layout == "named" else travel
        up = _move_s(
            up_travel,
            float(c["vel"] if "vel" in c else c["up_vel"]),
            float(c.get("up_acc", c["acc"])),
        )
        settle = rng.uniform(0.02, 0.06)
        bottom = start + len(down) * STEP_S + settle
        end = bottom + float(c["hold"]) + len(up) * STEP_S + settle
        if _sounds(sc, k, c, rng):
            ratio = (
                1.0 if sc.layout != "soft" else rng.uniform(0.5, 0.9)
            )  # soft finger: key lags the arm
            trigger = float(c["distance"]) + rng.uniform(0.004, 0.009) / ratio
            step = min(int(np.searchsorted(down, min(trigger, travel))), len(down) - 1)
            t_on = start + step * STEP_S + rng.uniform(0.001, 0.004)
            rise = min(int(np.searchsorted(up, 0.3 * up_travel)), len(up) - 1)
            t_off = bottom + float(c["hold"]) + rise * STEP_S + rng.uniform(0.001, 0.004)
            if rng.random() < sc.late_release:
                t_off = end + rng.uniform(0.1, 0.4)
            velocity = rng.randint(1, 100)
            stroke.events.append(("on", key, velocity, round(t_on * 1000)))
            if rng.random() < sc.double_strike:
                stroke.events.append(
                    (
                        "on",
                        key,
                        max(1, velocity // 2),
                        round((t_on + rng.uniform(0.03, 0.09)) * 1000),
                    )
                )
                stroke.events.append(("off", key, 64, round(t_off * 1000)))
            stroke.events.append(
                ("off", key, rng.randint(1, 110), round(t_off * 1000) + rng.randint(0, 2))
            )
            stroke.events.sort(key=lambda e: e[3])
            stroke.printed_on = [-1] * len(stroke.events)
            for j, (kind, note, vel, t) in enumerate(stroke.events):
                fifo.append((t, 0x90 if kind == "on" else 0x80, note, vel, stroke, j))
            fifo.sort(key=lambda e: e[0])
        read_at = round((end + rng.uniform(0.005, 0.04)) * 1000)
        ready = [e for e in fifo if e[0] <= read_at][: sc.read_size]
        for e in ready:
            fifo.remove(e)
            e[4].printed_on[e[5]] = stroke.line
        lines.append(_line_text(sc, c, k, [(s, n, v, t) for t, s, n, v, *_ in ready]))
        strokes.append(stroke)
        clock = read_at / 1000 + overhead + rng.gauss(0.0, 0.02 + 0.02 * overhead)
    return TruthLog("\n".join(lines) + "\n", strokes)


def _sounds(sc: Scenario, k: int, c: dict[str, float | str], rng: random.Random) -> bool:
    if sc.sound == "fast-late":
        return k >= sc.n * 0.6 and float(c.get("vel", c.get("down_vel", 0.0))) >= 0.05
    return rng.random() < float(sc.sound)


def check_assignment(truth: TruthLog, trials: object, midi: object) -> list[str]:
    """Differences between the importer's trials/MIDI tables and the truth (empty: exact).

    An `ok` line must hold exactly the events its stroke printed; a `silent` line must be a silent
    stroke; a stroke whose events were never read must not be called silent or ok (the importer may
    also flag a silent stroke it cannot prove silent as unread). Lines the importer calls
    undecided are not counted here (see `undecided`): a doubt said aloud is not a wrong answer.
    """
    import pandas as pd

    assert isinstance(trials, pd.DataFrame) and isinstance(midi, pd.DataFrame)
    problems = []
    by_line = truth.by_line()
    events = {line: set() for line in by_line}
    index_line = dict(zip(trials["index"], trials["source_line"], strict=True))
    for row in midi.itertuples():
        if row.index >= 0:
            kind = "on" if row.type == "note_on" else "off"
            events[index_line[row.index]].add((kind, round(row.t_s * 1000), int(row.velocity)))
    for row in trials.itertuples():
        stroke = by_line[row.source_line]
        truth_outcome = stroke.outcome
        if row.status == "ok":
            if truth_outcome != "ok" or events[row.source_line] != stroke.printed():
                problems.append(
                    f"line {row.source_line}: ok with {sorted(events[row.source_line])}, truth "
                    f"{truth_outcome} {sorted(stroke.printed())}"
                )
        elif row.status == "silent":
            if truth_outcome != "silent":
                problems.append(f"line {row.source_line}: silent, truth {truth_outcome}")
        elif row.assignment == "unread" and truth_outcome == "ok":
            problems.append(f"line {row.source_line}: unread, truth ok")
        elif row.assignment not in ("unread", "undecided"):
            problems.append(
                f"line {row.source_line}: {row.status}/{row.assignment}, truth {truth_outcome}"
            )
    return problems


def undecided(trials: object) -> int:
    """How many lines the importer left undecided."""
    import pandas as pd

    assert isinstance(trials, pd.DataFrame)
    return int((trials["assignment"] == "undecided").sum())


def lost_events(truth: TruthLog) -> int:
    return sum(1 for s in truth.strokes for line in s.printed_on if line < 0)


__all__ = [
    "Scenario",
    "Stroke",
    "TruthLog",
    "check_assignment",
    "lost_events",
    "make_log",
    "tiled_text",
    "undecided",
]


def tiled_text(truth: TruthLog, lines: int) -> str:
    """The log repeated until it has `lines` lines, each copy later on the same MIDI clock.

    For size benchmarks: a long run of the same script (no restart), with the structure (backlogs,
    silences) of the original.
    """
    import ast

    records = [ast.literal_eval(line) for line in truth.text.splitlines()]
    span = max((t for r in records if "midi" in r for _, t in r["midi"]), default=0) + 5000
    out: list[str] = []
    copy = 0
    while len(out) < lines:
        shift = copy * span
        for record in records:
            if "midi" not in record:
                continue
            shifted = dict(record, midi=[[m, t + shift] for m, t in record["midi"]])
            out.append(repr(shifted))
            if len(out) == lines:
                break
        copy += 1
    return "\n".join(out) + "\n"
