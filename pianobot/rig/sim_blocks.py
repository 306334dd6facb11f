"""What a simulated sweep needs to run its blocks of keystrokes on other processes.

A simulated sweep is sequential only through its clock: when a keystroke starts depends on
when the arm came back from the one before, on vacuum changes, moves and injected faults. The
expensive part of a keystroke (its physics, observation and readout) depends on its own
parameters and start time only. So a parallel sweep runs twice:

1. the timeline, in the driver: the same station, faults and retries on a rig whose world is a
   `TimingWorld` that only knows when each arm comes back and each key is ready again (worked
   out by `keystroke_times` in the workers), which is cheap and gives every block's start state;
2. the blocks, on the workers: a fresh simulated rig is `restore`d to the block's start state,
   the keystrokes of earlier blocks whose MIDI or mocap could still reach into this block are
   `replay`ed into the device buffers, and the block runs as it would have in one process.

A restored rig ends a block in the state the timeline predicted; the driver checks that.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pianobot.physics.trajectory import Press
from pianobot.rig.sim import SimArm, _retrigger_m, make_world, stroke_times
from pianobot.rig.station import Rig

# How far past a keystroke's settled truth its observations can reach: the mocap clock offset
# and MIDI jitter are added to this.
_MARGIN_S = 1e-3


@dataclass(frozen=True)
class SimSnapshot:
    """The state a simulated rig carries from one keystroke to the next."""

    clock_s: float
    vacuum_kpa: float
    presses_sent: int
    stop_armed: bool
    key_ready_s: tuple[tuple[int, float], ...]
    connected: bool
    connects: int
    arm_note: int | None
    station_vacuum_kpa: float | None
    station_vacuum_measured_kpa: float | None
    station_hover: tuple[int, float] | None


@dataclass(frozen=True)
class KeystrokeCall:
    """One keystroke the world was asked for: enough to replay its observations."""

    press: Press
    vacuum_kpa: float
    note: int
    t0_s: float
    key: str
    end_s: float  # run-clock time after which none of its observations can land


@dataclass(frozen=True)
class KeystrokeTimes:
    """When, after motion start, the arm is back and the key is ready; how long it is observed."""

    arm_back_s: float
    key_ready_s: float
    observed_s: float


@dataclass(frozen=True)
class _TimedStroke:
    times: tuple[float, float]
    t0_s: float
    midi: tuple[Any, ...] = ()
    mocap_t_s: Any = field(default_factory=lambda: np.empty(0))
    mocap_x0_m: Any = field(default_factory=lambda: np.empty(0))
    mocap_x1_m: Any = field(default_factory=lambda: np.empty(0))
    mocap_x2_m: Any = field(default_factory=lambda: np.empty(0))
    truth_t_s: Any = field(default_factory=lambda: np.empty(0))
    truth_x0_m: Any = field(default_factory=lambda: np.empty(0))
    truth_x1_m: Any = field(default_factory=lambda: np.empty(0))
    truth_x2_m: Any = field(default_factory=lambda: np.empty(0))
    arm_t_s: Any = field(default_factory=lambda: np.empty(0))
    arm_x0_m: Any = field(default_factory=lambda: np.empty(0))
    key_speed_at_trigger_mps: float = float("nan")
    max_key_travel_m: float = float("nan")


class TimingWorld:
    """A world for a sweep's timeline: keystrokes take their times from a table, nothing else.

    Everything but `keystroke` is the real world's (vacuum settling, the piano's re-trigger
    depth). Each keystroke asked for is recorded in `calls`.
    """

    def __init__(self, world: Any, times: dict[tuple[Press, float], KeystrokeTimes]) -> None:
        self.world = world
        self.model = world.model
        self.times = times
        self.calls: list[KeystrokeCall] = []
        config = getattr(world, "config", None)
        mocap = getattr(config, "mocap", None)
        offset = float(getattr(mocap, "clock_offset_s", 0.0)) + float(
            getattr(world.model, "mocap_delay_s", 0.0))
        self._reach_s = max(offset, 0.0) + float(getattr(config, "midi_jitter_s", 0.0)) + _MARGIN_S

    def vacuum_settle_s(self, from_kpa: float, to_kpa: float) -> float:
        return float(self.world.vacuum_settle_s(from_kpa, to_kpa))

    def keystroke(
        self, press: Press, vacuum_kpa: float, *, note: int = 57, t0_s: float = 0.0,
        key: str = "", block: str | None = None,
    ) -> _TimedStroke:
        t = self.times[(press, float(vacuum_kpa))]
        self.calls.append(KeystrokeCall(press, float(vacuum_kpa), int(note), float(t0_s), key,
                                        float(t0_s) + t.observed_s + self._reach_s))
        return _TimedStroke(times=(t.arm_back_s, t.key_ready_s), t0_s=float(t0_s))


def keystroke_times(world: Any, keystrokes: Sequence[tuple[Press, float]],
                    kept: dict[Any, Any] | None = None) -> dict[tuple[Press, float], KeystrokeTimes]:
    """The times of every distinct (press, vacuum) in `keystrokes`, from its simulated truth;
    `kept` receives those truths (`World.prefetched`), for the block's run to `adopt`."""
    unique = list(dict.fromkeys((press, float(v)) for press, v in keystrokes))
    world.prefetch([p for p, _ in unique], [v for _, v in unique])
    if kept is not None:
        kept.update(world.prefetched())
    retrigger = _retrigger_m(world)
    out: dict[tuple[Press, float], KeystrokeTimes] = {}
    for press, vacuum in unique:
        truth = world.settled_truth(press, vacuum)  # the times depend on the truth only
        back, ready = stroke_times(truth, press, retrigger)
        out[(press, vacuum)] = KeystrokeTimes(back, ready, truth.duration_s)
    return out


def world_for(rig_spec: Any, seed: int) -> Any:
    """The physics World the simulated rig of `rig_spec` would build (for a worker's rig)."""
    return make_world(rig_spec.world, seed)


def _arm(rig: Rig) -> SimArm:
    if not isinstance(rig.arm, SimArm):
        raise TypeError(f"a {rig.kind} rig has no simulated state to save")
    return rig.arm


def snapshot(rig: Rig) -> SimSnapshot:
    """The simulated rig's carried state (clock, vacuum, hover, fault counters, key readiness)."""
    arm = _arm(rig)
    state, station = arm.state, rig.station
    return SimSnapshot(
        clock_s=float(state.clock.now()),
        vacuum_kpa=float(state.vacuum_kpa),
        presses_sent=int(state.presses_sent),
        stop_armed=bool(state.stop_armed),
        key_ready_s=tuple(sorted(state.key_ready_s.items())),
        connected=arm.connected,
        connects=arm.connects,
        arm_note=arm.note,
        station_vacuum_kpa=station.vacuum_kpa,
        station_vacuum_measured_kpa=station._vacuum_measured_kpa,
        station_hover=station.hover,
    )


def restore(rig: Rig, snap: SimSnapshot) -> None:
    """Put a freshly built simulated rig into the state `snap` describes."""
    arm = _arm(rig)
    state, station = arm.state, rig.station
    state.clock._t_s = snap.clock_s  # the sim's own virtual clock
    state.vacuum_kpa = snap.vacuum_kpa
    state.presses_sent = snap.presses_sent
    state.stop_armed = snap.stop_armed
    state.key_ready_s = dict(snap.key_ready_s)
    arm.connected, arm.connects, arm.note = snap.connected, snap.connects, snap.arm_note
    station._vacuum_kpa = snap.station_vacuum_kpa
    station._vacuum_measured_kpa = snap.station_vacuum_measured_kpa
    station._hover = snap.station_hover


def replay(rig: Rig, calls: Sequence[KeystrokeCall]) -> None:
    """Feed the device buffers with the observations of earlier keystrokes (no clock, no records)."""
    arm = _arm(rig)
    state = arm.state
    for call in calls:
        state.key = call.key
        stroke = state.world.keystroke(call.press, call.vacuum_kpa, note=call.note, t0_s=call.t0_s,
                                       key=call.key)
        arm._publish(stroke)
    state.truth, state.extra = None, {}
