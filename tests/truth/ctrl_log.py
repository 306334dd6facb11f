"""MIDI-only sessions written as the study's `ctrl_midi` keystroke logs (one dict per line).

    {'control': [60, 45, 0.5, 0.03, 0.04, 0.05, 0], 'midi': [[[144, 57, 1, 0], 468620], ...]}

The study's script, per keystroke: move down by distance + depth at (vel, acc), hold, move up by
the same, then `pygame.midi.Input.read(2)` and print the control list with what the read
returned; then the next keystroke after a short pause. Reproduced here: each keystroke is
simulated from rest (the key has long settled between keystrokes), its events are put on the MIDI
clock (ms since MIDI init, latency + jitter, integer ms), and a FIFO drained by at most two events
per line decides what each line prints — a note-off that comes after the read, or a third event,
spills into the next line, as in the real logs. Silent keystrokes print `[]`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .arm import PressCommand
from .plant import Plant
from .readout import NoteEvent, Piano, read_key

NOTE_ON, NOTE_OFF = 144, 128
READ_SIZE = 2
RECORD_EVERY = 4  # record every 4 steps (≈ 83 µs) for the piano's contacts
SETTLE_S = 0.6  # simulated after the arm is back up (the key returns and rings out)


@dataclass(frozen=True)
class Stroke:
    """One simulated keystroke: what was commanded, what the piano sent, and the key's extremes."""

    press: PressCommand
    events: tuple[NoteEvent, ...]
    max_key_travel_m: float
    contact_speed_mps: float  # finger speed relative to the key at first touch (NaN: no touch)
    events_located: int
    unresolved: int


def simulate_stroke(plant: Plant, press: PressCommand, piano: Piano) -> Stroke:
    """Simulate one keystroke from rest (motion start at t = 0) and read the piano."""
    local = PressCommand(0.0, press.speed_mps, press.acceleration_mps2, press.depth_m,
                         press.distance_m, press.hold_s, press.up_speed_mps)  # fmt: skip
    traj = plant.simulate(local.moves(), local.t_end_s + SETTLE_S, record_every=RECORD_EVERY)
    t, x2 = traj.t_s, traj["x2_m"]
    gap = traj["x1_m"] - x2 - plant.distance_m
    touch = np.flatnonzero(gap > 0)
    speed = float(traj["v1_mps"][touch[0]] - traj["v2_mps"][touch[0]]) if touch.size else math.nan
    events = read_key(piano, t, x2)
    return Stroke(press, tuple(events), float(np.max(x2)), speed, traj.events, traj.unresolved)


@dataclass(frozen=True)
class Session:
    """A whole log: strokes with their motion starts on the MIDI clock, and the lines to write."""

    strokes: tuple[Stroke, ...]
    starts_s: tuple[float, ...]  # motion start of each keystroke on the MIDI clock
    lines: tuple[str, ...]


def control_list(press: PressCommand, vacuum_kpa: float, angle_deg: float) -> list[float]:
    """The soft-2022 control layout: [|vacuum|, angle, acc, vel, depth, distance, hold]."""
    vac = abs(vacuum_kpa)
    vac_out: float = int(vac) if float(vac).is_integer() else float(vac)
    hold: float = int(press.hold_s) if float(press.hold_s).is_integer() else float(press.hold_s)
    return [vac_out, int(angle_deg), float(press.acceleration_mps2), float(press.speed_mps),
            float(press.depth_m), float(press.distance_m), hold]  # fmt: skip


def assemble(
    strokes: list[Stroke],
    vacuum_kpa: float,
    angle_deg: float,
    piano: Piano,
    rng: np.random.Generator,
    first_start_s: float,
    pause_s: float,
    pause_sd_s: float,
    read_delay_s: float = 0.03,
) -> Session:
    """Put strokes on the MIDI clock and print the lines the script would have printed."""
    starts: list[float] = []
    stamped: list[tuple[int, int, int, int]] = []  # (t_ms, order, status, velocity)
    reads: list[float] = []
    t = first_start_s
    order = 0
    for stroke in strokes:
        starts.append(t)
        for event in stroke.events:
            t_ms = math.floor((t + event.t_s + rng.normal(0.0, piano.jitter_s)) * 1000.0)
            status = NOTE_ON if event.kind == "note_on" else NOTE_OFF
            stamped.append((t_ms, order, status, event.velocity))
            order += 1
        end = t + stroke.press.t_end_s - stroke.press.t_start_s
        reads.append(end + read_delay_s)
        t = end + max(0.2, pause_s + rng.normal(0.0, pause_sd_s))
    stamped.sort()
    queue = list(stamped)
    lines = []
    for stroke, read_at in zip(strokes, reads, strict=True):
        got = []
        while queue and len(got) < READ_SIZE and queue[0][0] <= read_at * 1000.0:
            t_ms, _, status, vel = queue.pop(0)
            got.append([[status, piano.note, vel, 0], t_ms])
        control = control_list(stroke.press, vacuum_kpa, angle_deg)
        lines.append(repr({"control": control, "midi": got}))
    return Session(tuple(strokes), tuple(starts), tuple(lines))


def write_log(path: Path, session: Session) -> None:
    path.write_text("".join(line + "\n" for line in session.lines), encoding="utf-8")
