"""The hardware layer: device protocols, the simulated rig, the UR5 lab, and `open_rig`.

`open_rig(rig_spec)` is the only place that chooses a backend; everything above the rig layer
sees a `Rig` made of protocol-typed devices.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from pianobot.rig.station import Rig, Station, StationSettings, TrialLike

__all__ = ["Rig", "Station", "StationSettings", "TrialLike", "open_rig"]


@contextmanager
def open_rig(rig_spec: Any, *, seed: int | None = None, world: Any | None = None) -> Iterator[Rig]:
    """Open the rig a RigSpec describes; on exit (also on errors or Ctrl-C) leave it safe.

    Args:
        rig_spec: a `pianobot.spec.RigSpec` (kind `sim` or `ur5`).
        seed: overrides the rig file's seed (the simulated world's noise and faults).
        world: a physics World to use instead of the rig file's (sim only; for tests).

    On exit the arm is stopped and retracted and the vacuum vented, whatever happened inside.
    """
    rig = _build(rig_spec, seed=seed, world=world)
    try:
        yield rig
    finally:
        rig.close()


def _build(rig_spec: Any, *, seed: int | None, world: Any | None) -> Rig:
    chosen_seed = int(rig_spec.seed if seed is None else seed)
    if rig_spec.kind == "sim":
        from pianobot.rig.sim import build_sim_rig

        return build_sim_rig(rig_spec, chosen_seed, world=world)
    if rig_spec.kind == "ur5":
        return _build_lab(rig_spec)
    raise ValueError(f"unknown rig kind {rig_spec.kind!r}")


def _build_lab(rig_spec: Any) -> Rig:
    """The UR5 lab: devices from `pianobot.rig.lab` (vendor SDKs load only here)."""
    from pianobot.rig.lab import open_lab_devices

    arm, vacuum, keyboard, mocap, clock = open_lab_devices(rig_spec)
    settle = rig_spec.settle_s
    station = Station(
        arm, vacuum, keyboard, mocap, clock,
        StationSettings(
            settle_s=settle.between_presses_s,
            after_vacuum_change_s=settle.after_vacuum_change_s,
        ),
    )
    # open_lab_devices has connected the arm and started the MIDI input already.
    return Rig(
        kind="ur5",
        arm=arm,
        vacuum=vacuum,
        keyboard=keyboard,
        mocap=mocap,
        clock=clock,
        station=station,
        description={"host": rig_spec.ur5.host if rig_spec.ur5 is not None else None},
    )
