"""The fastest tempo a finger can physically sustain for a song: a reference for `play`'s choice.

Defined on the simulated world itself (its truth, which the planner never sees), by brute force:

1. Truth tables: for every vacuum level, the world plays strokes over a grid of down velocities
   in several shapes — plain presses from hovers of 1 to 10 mm, and two-segment presses that
   approach at travel speed from those hovers to 1 mm above the key — at the press depth play
   uses; per stroke the reference records its MIDI velocity, the note-on time (motion start →
   note-on), when the key is back above the piano's re-trigger depth for good (read from the
   world's key trace, as the simulated rig does before it lets the same key be struck again)
   and when the arm is back up (the exact moveL timing). Any stroke may serve any note.
2. Targets: the song's velocities mapped linearly onto the loudness range the world really
   reaches with that level and geometry; a stroke is acceptable for a note when its velocity is
   within `tolerance` MIDI steps of the target (one step: the piano's own resolution).
3. Brute force over strokes, bisection over tempos: a dynamic programme over every acceptable
   stroke of every note asks whether some choice starts every note exactly on time (each press
   starts at its onset minus its note-on time, after the arm is back up from the previous press
   and has moved to the key, and, on the same key, after the key is back above the re-trigger
   depth). Holds are free to be zero. Slower never hurts, so the fastest tempo that works is
   found by bisection (to `resolution_bpm`); the best over vacuum levels is the finger's.

Nothing here comes from `pianobot.play`'s model, tables, feasibility formula or scheduler.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pianobot.io.midifile import Note
from pianobot.physics.trajectory import Press, press_duration_s
from pianobot.plan import key_change_s
from pianobot.spec import RigSpec

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class TruthTable:
    """What the world does for the strokes of one vacuum level (one entry per stroke)."""

    vacuum_kpa: float
    speeds_mps: FloatArray
    velocity: FloatArray  # MIDI on-velocity, NaN when silent
    lead_s: FloatArray  # motion start → note-on
    ready_s: FloatArray  # motion start → key above the re-trigger depth for good
    busy_s: FloatArray  # motion start → arm back up


# Stroke shapes: (hover m, fast approach to 1 mm above the key?) at the play depth.
SHAPES = ((0.001, False), (0.002, False), (0.005, False), (0.01, False),
          (0.002, True), (0.005, True), (0.01, True))
GAP_M = 0.001
TRAVEL = (0.5, 4.0)  # the fast approach's speed and acceleration (a player's travel moves)


def strokes(depth_m: float, speeds_mps: Sequence[float], *, acceleration_mps2: float = 2.0,
            up_velocity_mps: float = 0.7) -> list[Press]:
    """Every stroke shape at every speed (a fast approach only where it ends above the key
    with room for the contact-speed move to reach its speed)."""
    out = []
    for hover, fast in SHAPES:
        for v in speeds_mps:
            gap = max(GAP_M, 1.25 * v * v / (2 * acceleration_mps2))
            if fast and hover - gap < 1e-3:
                continue
            out.append(Press(hover, depth_m, float(v), up_velocity_mps, acceleration_mps2, 0.0,
                             approach_m=hover - gap if fast else 0.0, travel_velocity_mps=TRAVEL[0],
                             travel_acceleration_mps2=TRAVEL[1]))
    return out


def truth_table(world: object, vacuum_kpa: float, presses: Sequence[Press]) -> TruthTable:
    """Play each press in `world` (a `pianobot.physics.world.World`) at one vacuum level."""
    release = world.model.readout_params().release_m  # type: ignore[attr-defined]
    velocity, lead, ready, busy = [], [], [], []
    for j, stroke in enumerate(presses):
        k = world.keystroke(stroke, vacuum_kpa, note=60, key=f"reference-{j}")  # type: ignore[attr-defined]
        ons = [e for e in k.midi if e.type == "note_on"]
        velocity.append(float(ons[0].velocity) if ons else math.nan)
        lead.append(ons[0].t_s - k.t0_s if ons else math.nan)
        t = np.asarray(k.truth_t_s) - k.t0_s
        deep = np.nonzero(np.asarray(k.truth_x2_m) >= release)[0]
        ready.append(float(t[min(deep[-1] + 1, t.size - 1)]) if deep.size else 0.0)
        busy.append(press_duration_s(stroke))
    return TruthTable(vacuum_kpa, np.array([p.down_velocity_mps for p in presses]), np.array(velocity),
                      np.array(lead), np.array(ready), np.array(busy))


@dataclass(frozen=True)
class Reference:
    """The fastest sustainable tempo and how it was found."""

    bpm: float
    vacuum_kpa: float
    targets: FloatArray


def _acceptable(table: TruthTable, targets: FloatArray, tolerance: float) -> npt.NDArray[np.bool_]:
    """(notes × speeds): strokes whose velocity is within `tolerance` of each note's target."""
    v = table.velocity
    ok = np.abs(v[None, :] - targets[:, None]) <= tolerance + 1e-9
    for i in np.nonzero(~ok.any(axis=1))[0]:  # beyond the reach: the nearest loudness it has
        gap = np.abs(v - targets[i])
        ok[i] = gap <= np.nanmin(gap) + 1e-9
    return ok & np.isfinite(v)[None, :]


def _feasible(scale: float, onset: FloatArray, pitch: Sequence[int], moves: FloatArray, table: TruthTable,
              ok: npt.NDArray[np.bool_]) -> bool:
    """Is there a stroke per note so every note starts exactly on time at this time scale?"""
    lead, ready, busy = table.lead_s, table.ready_s, table.busy_s
    alive = ok[0].copy()
    for i in range(1, onset.size):
        gap = (onset[i] - onset[i - 1]) * scale
        # start_i − start_p = gap − lead_i + lead_p must cover what the previous stroke needs.
        room = gap - lead[None, :] + lead[:, None]  # (previous k', this k)
        need = busy[:, None] + moves[i]
        if pitch[i] == pitch[i - 1]:
            need = np.maximum(need, ready[:, None])
        fits = (room >= need - 1e-9) & alive[:, None] & ok[i][None, :]
        alive = fits.any(axis=0)
        if not alive.any():
            return False
    return True


def fastest_sustainable_bpm(notes: Sequence[Note], written_bpm: float, tables: Sequence[TruthTable], rig: RigSpec,
                            *, tolerance: float = 1.0, resolution_bpm: float = 0.05) -> Reference:
    """The brute-force reference (see the module doc); `notes` on the written time axis."""
    onset = np.array([n.onset_s for n in notes], dtype=np.float64)
    pitch = [n.pitch for n in notes]
    moves = np.zeros(len(notes))
    for i in range(1, len(notes)):
        if pitch[i] != pitch[i - 1]:
            moves[i] = key_change_s(pitch[i - 1], pitch[i], rig)
    song = np.array([n.velocity for n in notes], dtype=np.float64)
    best = Reference(0.0, math.nan, np.zeros(0))
    for table in tables:
        heard = table.velocity[np.isfinite(table.velocity)]
        if heard.size < 2:
            continue
        lo, hi = float(heard.min()), float(heard.max())
        span = song.max() - song.min()
        # One loudness throughout keeps its place on the MIDI scale 1-127 (velocity 64: the middle).
        targets = (np.full(song.shape, lo + (song[0] - 1) / 126 * (hi - lo)) if span <= 0
                   else lo + (song - song.min()) / span * (hi - lo))
        ok = _acceptable(table, targets, tolerance)
        slow, fast = 0.0, written_bpm  # feasible at `slow` (a standstill), unknown up to `fast`
        if _feasible(1.0, onset, pitch, moves, table, ok):
            slow = written_bpm
        while fast - slow > resolution_bpm and slow < written_bpm:
            middle = 0.5 * (slow + fast)
            if _feasible(written_bpm / middle, onset, pitch, moves, table, ok):
                slow = middle
            else:
                fast = middle
        if slow > best.bpm:
            best = Reference(slow, table.vacuum_kpa, targets)
    return best
