"""The fastest tempo a finger can physically sustain for a song: a reference for `play`'s choice.

Defined on the simulated world itself (its truth, which the planner never sees), by brute force:

1. Truth tables: for every vacuum level and stroke geometry the planner may use, the world
   plays strokes over a fine grid of down velocities; per stroke the reference records its MIDI
   velocity, the note-on time (motion start → note-on), when the key is back above the piano's
   re-trigger depth for good (read from the world's key trace, as the simulated rig does before
   it lets the same key be struck again) and when the arm is back up (the exact moveL timing).
2. Targets: the song's velocities mapped linearly onto the loudness range the world really
   reaches with that level and geometry; a stroke is acceptable for a note when its velocity is
   within `tolerance` MIDI steps of the target (one step: the piano's own resolution).
3. Brute force over tempos: from the written tempo down in small steps, a dynamic programme
   over every acceptable stroke of every note asks whether some choice starts every note
   exactly on time (each press starts at its onset minus its note-on time, after the arm is back
   up from the previous press and has moved to the key, and, on the same key, after the key is
   back above the re-trigger depth). Holds are free to be zero. The first tempo that works is
   the reference; the best over levels and geometries is the finger's.

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
    """What the world does for strokes of one level and geometry, over down velocities."""

    vacuum_kpa: float
    distance_m: float
    speeds_mps: FloatArray
    velocity: FloatArray  # MIDI on-velocity, NaN when silent
    lead_s: FloatArray  # motion start → note-on
    ready_s: FloatArray  # motion start → key above the re-trigger depth for good
    busy_s: FloatArray  # motion start → arm back up


def truth_table(world: object, vacuum_kpa: float, press: Press, speeds_mps: Sequence[float]) -> TruthTable:
    """Play `press` at each down velocity in `world` (a `pianobot.physics.world.World`)."""
    release = world.model.readout_params().release_m  # type: ignore[attr-defined]
    velocity, lead, ready, busy = [], [], [], []
    for j, v in enumerate(speeds_mps):
        stroke = Press(press.distance_m, press.depth_m, float(v), press.up_velocity_mps, press.acceleration_mps2, 0.0)
        k = world.keystroke(stroke, vacuum_kpa, note=60, key=f"reference-{j}")  # type: ignore[attr-defined]
        ons = [e for e in k.midi if e.type == "note_on"]
        velocity.append(float(ons[0].velocity) if ons else math.nan)
        lead.append(ons[0].t_s - k.t0_s if ons else math.nan)
        t = np.asarray(k.truth_t_s) - k.t0_s
        deep = np.nonzero(np.asarray(k.truth_x2_m) >= release)[0]
        ready.append(float(t[min(deep[-1] + 1, t.size - 1)]) if deep.size else 0.0)
        busy.append(press_duration_s(stroke))
    return TruthTable(vacuum_kpa, press.distance_m, np.asarray(speeds_mps, dtype=np.float64), np.array(velocity),
                      np.array(lead), np.array(ready), np.array(busy))


@dataclass(frozen=True)
class Reference:
    """The fastest sustainable tempo and how it was found."""

    bpm: float
    vacuum_kpa: float
    distance_m: float
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
                            *, tolerance: float = 1.0, step_bpm: float = 0.25) -> Reference:
    """The brute-force reference (see the module doc); `notes` on the written time axis."""
    onset = np.array([n.onset_s for n in notes], dtype=np.float64)
    pitch = [n.pitch for n in notes]
    moves = np.zeros(len(notes))
    for i in range(1, len(notes)):
        if pitch[i] != pitch[i - 1]:
            moves[i] = key_change_s(pitch[i - 1], pitch[i], rig)
    song = np.array([n.velocity for n in notes], dtype=np.float64)
    best = Reference(0.0, math.nan, math.nan, np.zeros(0))
    for table in tables:
        heard = table.velocity[np.isfinite(table.velocity)]
        if heard.size < 2:
            continue
        lo, hi = float(heard.min()), float(heard.max())
        span = song.max() - song.min()
        targets = np.full(song.shape, 0.5 * (lo + hi)) if span <= 0 else lo + (song - song.min()) / span * (hi - lo)
        ok = _acceptable(table, targets, tolerance)
        steps = 0
        while written_bpm - steps * step_bpm > step_bpm and not _feasible(
                written_bpm / (written_bpm - steps * step_bpm), onset, pitch, moves, table, ok):
            steps += 1
        bpm = written_bpm - steps * step_bpm
        if bpm > best.bpm:
            best = Reference(bpm, table.vacuum_kpa, table.distance_m, targets)
    return best
