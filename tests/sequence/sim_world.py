"""Sequence-mode strokes on pianobot's simulated world (the own-world suite, reported apart).

The plan is the spec's sequence mode (`sweep: {mode: sequence, …}` expanded as `pianobot sweep`
expands it: random notes, every parameter drawn per stroke, in order). The default world keeps
no state between keystrokes (each starts from rest; the stiffness drift is one per vacuum
level). Here each sequence is its own stiffness-drift block with up to 30 % drift — the soft
finger re-stiffened between sequences — so the strokes of a sequence share a finger state:
context matters. The piano's velocity curve is made linear and more sensitive than the default
so that the soft finger's strokes span a useful range of MIDI velocities.
"""

from __future__ import annotations

import pandas as pd

from pianobot.analysis.sequence.collect import play_on_world
from pianobot.physics.effects import Effects
from pianobot.physics.world import World, WorldConfig
from pianobot.plan import expand, plan_frame
from pianobot.spec import parse_spec_text

PIANO = {"curve_exponent": 1.0, "full_scale_speed_mps": 0.03, "curve_saturation": 0.0}
SPEC = """
name: context-world
rig: sim
finger: soft
sweep:
  mode: sequence
  sequences: {sequences}
  length: {length}
  seed: {seed}
  params:
    note: [60, 62, 64, 65, 67, 69, 71]
    down_velocity_mps: {{low: 0.02, high: 0.06}}
    hold_s: {{low: 0.0, high: 0.2}}
    distance_m: {{low: 0.003, high: 0.012}}
  fixed:
    vacuum_kpa: -80
    depth_m: 0.035
    acceleration_mps2: 1.0
record: [midi]
"""


def context_world_trials(n_sequences: int, *, length: int = 8, stiffness_per_sequence: bool = True,
                         seed: int = 3) -> pd.DataFrame:
    effects = Effects.default_world().with_effect("stiffness_drift", drift_fraction=0.3)
    world = World(WorldConfig(effects=effects.to_dict(), piano=PIANO), seed=1)
    spec = parse_spec_text(SPEC.format(sequences=n_sequences, length=length, seed=seed), "context-world spec")
    plan = plan_frame(expand(spec))
    return play_on_world(world, plan, stiffness_per_sequence=stiffness_per_sequence)
