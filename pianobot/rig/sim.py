"""The simulated rig: arm, vacuum, keyboard and mocap sharing one physics `World`.

A press runs `world.keystroke(...)` once and feeds every device from that one result, so the
arm trace, the MIDI note and the mocap trace of a keystroke are consistent with each other (the
ophyd-async sim pattern: devices share one generator). Time is a `VirtualClock`; a keystroke is
a pure function of (world config, seed, press, vacuum, note, key) where key = trial id and
attempt, so a redone trial after a crash reproduces the uninterrupted run exactly.

The arm is free again when it is back at its hover height (the world's arm trace), not when the
key has come to rest: the key returns and rings on its own. The world simulates every keystroke
from a key at rest, so a re-strike of the same key must not start while that key is still below
its re-trigger depth (the piano's release depth, where the note-off fires and a new note can
start): the arm waits until the previous stroke's key trace has risen above it for good, and the
press record says how long it waited. The residual motion above that depth (under a millimetre)
and the finger's own ringing are not carried into the next stroke.

Injected faults (rig file `faults:`):
- `drop_connection_every_n_presses: N` — every N-th press sent loses the link half-way down
  (ConnectionLost); the arm must `connect()` again.
- `protective_stop_at_trial: k` — the press of the trial with plan index k triggers a
  protective stop (SafetyStop), once. The operator "clears" it by resuming the run: the runner
  calls `Rig.clear_stop()`, which for the sim disarms the fault (it is recorded in run.json, so
  it fires once per run folder); on the UR5 the stop is acknowledged on the pendant first.
- `midi_loss_prob: q` — each MIDI message is lost with probability q.
- `mocap_drop_prob: q` — each mocap frame is dropped (NaN) with probability q.
Fault randomness is seeded by (rig seed, key), so it too repeats exactly for a redone trial.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from pianobot.physics._observe_kernel import last_beyond
from pianobot.physics.trajectory import Press, press_duration_s
from pianobot.plan import key_change_s
from pianobot.rig.clock import VirtualClock
from pianobot.rig.errors import ConnectionLost, SafetyStop
from pianobot.rig.protocols import FloatArray, KeystrokeResult, MidiEvent, PressRecord, Trace
from pianobot.rig.station import Rig, Station, StationSettings, TrialLike

# Events and frames older than this before a query window can no longer be asked for: dropping
# them keeps memory flat over a 100,000-trial sweep.
BUFFER_HORIZON_S = 60.0
# The arm counts as back up once its truth trace stays within this of the hover height.
ARM_AT_REST_M = 2e-5
# Re-trigger depth when a world does not say (a digital piano's release contact, ~1 mm).
DEFAULT_RETRIGGER_M = 1e-3


@dataclass(frozen=True)
class SimFaults:
    """Fault injection settings (all off by default)."""

    drop_connection_every_n_presses: int | None = None
    protective_stop_at_trial: int | None = None
    midi_loss_prob: float = 0.0
    mocap_drop_prob: float = 0.0


@dataclass
class SimState:
    """What the simulated devices share: the world, the clock, the current key and the buffers."""

    world: Any  # pianobot.physics.world.World (duck-typed: keystroke, vacuum_settle_s)
    clock: VirtualClock
    seed: int
    faults: SimFaults
    vacuum_kpa: float = 0.0
    key: str = "0"
    trial_index: int | None = None
    presses_sent: int = 0
    stop_armed: bool = True
    midi: list[MidiEvent] = field(default_factory=list)
    mocap: list[Trace] = field(default_factory=list)
    truth: Trace | None = None
    extra: dict[str, float] = field(default_factory=dict)
    key_ready_s: dict[int, float] = field(default_factory=dict)  # note -> key above re-trigger depth

    def rng(self, stream: str) -> np.random.Generator:
        """A generator seeded by (seed, key, stream): the same draws for a redone keystroke."""
        digest = hashlib.sha256(f"{self.seed}|{self.key}|{stream}".encode()).digest()
        return np.random.default_rng(int.from_bytes(digest[:8], "little"))


class SimArm:
    """A UR5 stand-in whose press runs the world's keystroke (implements `Arm`).

    Moves between keys take `travel_s(from_note, to_note)` (the plan's lab-time model: lift,
    traverse, lower), so a simulated run's lab time matches the dry-run estimate. The arm starts
    hovering over the first key, as the operator leaves it after calibration.
    """

    def __init__(self, state: SimState, travel_s: Callable[[int, int], float] | None = None) -> None:
        self.state = state
        self.travel_s = travel_s
        self.connected = False
        self.connects = 0
        self.note: int | None = None
        self._retrigger: tuple[Any, float] | None = None  # (world, its re-trigger depth)

    def connect(self) -> None:
        self.connected = True
        self.connects += 1

    def move_to_key(self, note: int, distance_m: float) -> None:
        self._require_link()
        if self.note is not None and note != self.note and self.travel_s is not None:
            self.state.clock.sleep(self.travel_s(self.note, note))
        self.note = note

    def press(self, press: Press, note: int) -> PressRecord:
        """Run one keystroke in the world; may raise an injected ConnectionLost or SafetyStop."""
        self._require_link()
        state = self.state
        state.presses_sent += 1
        t0_s = state.clock.now()
        faults = state.faults
        if state.stop_armed and faults.protective_stop_at_trial is not None and (
            state.trial_index == faults.protective_stop_at_trial
        ):
            state.stop_armed = False
            state.clock.sleep(0.2)
            raise SafetyStop(
                f"protective stop during the press of trial {state.trial_index} (injected fault)"
            )
        every = faults.drop_connection_every_n_presses
        if every and state.presses_sent % every == 0:
            self.connected = False
            state.clock.sleep(0.1)  # the link drops part-way down
            raise ConnectionLost(f"RTDE connection lost during press #{state.presses_sent} (injected fault)")
        warnings: tuple[str, ...] = ()
        wait_s = state.key_ready_s.get(note, -np.inf) - t0_s
        if wait_s > 0:
            # The key of the last stroke on this note is still below its re-trigger depth.
            state.clock.sleep(wait_s)
            t0_s = state.clock.now()
            warnings = (f"re-strike of note {note} waited {wait_s * 1e3:.0f} ms for the key to rise "
                        "above its re-trigger depth",)
        stroke = state.world.keystroke(press, state.vacuum_kpa, note=note, t0_s=t0_s, key=state.key)
        self._publish(stroke)
        back_s, ready_s = stroke_times(stroke, press, self._retrigger_m())
        t_up_s = t0_s + back_s
        state.key_ready_s[note] = t0_s + ready_s
        state.clock.sleep(t_up_s - state.clock.now())
        arm = Trace(t_s=_f64(stroke.arm_t_s), x0_m=_f64(stroke.arm_x0_m), source="arm")
        return PressRecord(t_start_s=t0_s, t_end_s=t_up_s, arm=arm, warnings=warnings)

    def _publish(self, stroke: Any) -> None:
        """Feed the keyboard's MIDI queue, the mocap buffer and the truth record from one stroke."""
        state = self.state
        events = [MidiEvent(float(e.t_s), str(e.type), int(e.note), int(e.velocity)) for e in stroke.midi]
        if state.faults.midi_loss_prob > 0 and events:
            keep = state.rng("midi-loss").random(len(events)) >= state.faults.midi_loss_prob
            events = [e for e, k in zip(events, keep, strict=True) if k]
        state.midi.extend(events)
        t_s = _f64(stroke.mocap_t_s)
        xs = [_f64(stroke.mocap_x0_m), _f64(stroke.mocap_x1_m), _f64(stroke.mocap_x2_m)]
        if state.faults.mocap_drop_prob > 0 and len(t_s):
            # A dropped frame: the markers were occluded, every coordinate of it is missing.
            dropped = state.rng("mocap-drop").random(len(t_s)) < state.faults.mocap_drop_prob
            xs = [np.where(dropped, np.nan, x) for x in xs]
        state.mocap.append(Trace(t_s=t_s, x0_m=xs[0], x1_m=xs[1], x2_m=xs[2], source="mocap"))
        state.truth = Trace(
            t_s=_f64(stroke.truth_t_s),
            x0_m=_f64(stroke.truth_x0_m),
            x1_m=_f64(stroke.truth_x1_m),
            x2_m=_f64(stroke.truth_x2_m),
            source="sim-truth",
        )
        state.extra = {
            "key_speed_at_trigger_mps": float(stroke.key_speed_at_trigger_mps),
            "max_key_travel_m": float(stroke.max_key_travel_m),
        }

    def _retrigger_m(self) -> float:
        """The world's re-trigger depth, worked out once per world (it is fixed)."""
        world = self.state.world
        if self._retrigger is None or self._retrigger[0] is not world:
            self._retrigger = (world, _retrigger_m(world))
        return self._retrigger[1]

    def _require_link(self) -> None:
        if not self.connected:
            raise ConnectionLost("the simulated arm is not connected; call connect()")

    def make_safe(self) -> None:
        """The simulated arm is always back at its start height between presses."""

    def close(self) -> None:
        self.connected = False

    def describe(self) -> dict[str, Any]:
        return {"kind": "sim-arm", "connects": self.connects}


class SimVacuum:
    """A regulator that takes the world's settling time to change level (implements `Vacuum`)."""

    def __init__(self, state: SimState) -> None:
        self.state = state

    def set_kpa(self, vacuum_kpa: float) -> float:
        settle_s = float(self.state.world.vacuum_settle_s(self.state.vacuum_kpa, vacuum_kpa))
        self.state.clock.sleep(settle_s)
        self.state.vacuum_kpa = float(vacuum_kpa)
        return float(vacuum_kpa)

    def vent(self) -> None:
        self.state.vacuum_kpa = 0.0

    def describe(self) -> dict[str, Any]:
        return {"kind": "sim-vacuum"}


class SimKeyboard:
    """MIDI input fed by the world (implements `Keyboard`)."""

    def __init__(self, state: SimState) -> None:
        self.state = state

    def start(self) -> None:
        """Nothing to open: events arrive from the shared state."""

    def events_between(self, t_from_s: float, t_to_s: float) -> list[MidiEvent]:
        events = self.state.midi
        found = [e for e in events if t_from_s <= e.t_s < t_to_s]
        horizon = t_from_s - BUFFER_HORIZON_S
        if events and events[0].t_s < horizon:
            self.state.midi = [e for e in events if e.t_s >= horizon]
        return sorted(found, key=lambda e: e.t_s)

    def close(self) -> None:
        self.state.midi.clear()

    def describe(self) -> dict[str, Any]:
        return {"kind": "sim-keyboard", "midi_loss_prob": self.state.faults.midi_loss_prob}


class SimMocap:
    """A 120 Hz motion-capture stream fed by the world (implements `Mocap`)."""

    def __init__(self, state: SimState) -> None:
        self.state = state
        self._buffer: list[Trace] | None = None  # the state's buffer that `_spans` describes
        self._spans: list[tuple[float, float, Trace]] = []  # (first, last frame time, chunk)

    def trace_between(self, t_from_s: float, t_to_s: float) -> Trace:
        spans = self._indexed()
        chunks = [c for first, last, c in spans if last >= t_from_s and first < t_to_s]
        horizon = t_from_s - BUFFER_HORIZON_S
        if any(last < horizon for _, last, _ in spans):
            self._spans = [span for span in spans if span[1] >= horizon]
            self.state.mocap = self._buffer = [c for _, _, c in self._spans]
        if not chunks:
            empty = np.empty(0)
            return Trace(t_s=empty, x0_m=empty, x1_m=empty, x2_m=empty, source="mocap")
        if len(chunks) == 1 and chunks[0].t_s[0] >= t_from_s and chunks[0].t_s[-1] < t_to_s:
            # The usual case: one keystroke's frames, all inside the window (times increase).
            only = chunks[0]
            return Trace(t_s=only.t_s, x0_m=_column(only, "x0_m"), x1_m=_column(only, "x1_m"),
                         x2_m=_column(only, "x2_m"), source="mocap")
        t_s = np.concatenate([c.t_s for c in chunks])
        inside = (t_s >= t_from_s) & (t_s < t_to_s)

        def cut(name: str) -> FloatArray:
            return np.concatenate([_column(c, name) for c in chunks])[inside]

        return Trace(t_s=t_s[inside], x0_m=cut("x0_m"), x1_m=cut("x1_m"), x2_m=cut("x2_m"), source="mocap")

    def _indexed(self) -> list[tuple[float, float, Trace]]:
        """The buffered chunks with their first and last frame times as floats (a keystroke's
        chunk is looked at by every later window for a minute: its times are read once).

        The buffer only grows at its end between two calls (`SimArm._publish`); anything else
        done to it (a new list, a clear) is noticed and the spans are worked out again.
        """
        buffer, spans = self.state.mocap, self._spans
        if buffer is not self._buffer or len(spans) > len(buffer) or (
            spans and buffer[len(spans) - 1] is not spans[-1][2]
        ):
            self._buffer, spans = buffer, []
        for c in buffer[len(spans):]:
            # An empty chunk never matches a window and is dropped with the stale ones.
            spans.append((float(c.t_s[0]), float(c.t_s[-1]), c) if len(c.t_s) else (math.inf, -math.inf, c))
        self._spans = spans
        return spans

    def describe(self) -> dict[str, Any]:
        return {"kind": "sim-mocap", "mocap_drop_prob": self.state.faults.mocap_drop_prob}


def stroke_times(stroke: Any, press: Press, retrigger_m: float) -> tuple[float, float]:
    """(arm back at its hover height, key above its re-trigger depth), from motion start.

    A stroke that carries these already (`stroke.times`, a parallel sweep's timeline) gives
    them; otherwise they come from its truth trace. Both are read on the truth's own grid of
    times from motion start, so they do not depend on where the stroke falls on the run clock.
    """
    times = getattr(stroke, "times", None)
    if times is not None:
        return float(times[0]), float(times[1])
    rel = getattr(stroke, "rel_t_s", None)
    t_s = _f64(rel) if rel is not None else _f64(stroke.truth_t_s) - float(stroke.t0_s)
    return _arm_back_s(stroke, press, t_s), _key_ready_s(stroke, retrigger_m, t_s)


def _arm_back_s(stroke: Any, press: Press, t_s: FloatArray) -> float:
    """Motion start → the arm is back at its hover height (commanded profile, or later if it lags).

    The answer is a sample time of the world's truth trace, so run-clock times stay on the
    world's output grid (a resumed run then stamps MIDI exactly like the uninterrupted one).
    """
    if not t_s.size:
        return float(stroke.duration_s)
    away = last_beyond(_f64(stroke.truth_x0_m), ARM_AT_REST_M, True)
    last_s = float(t_s[away]) if away >= 0 else 0.0
    k = int(np.searchsorted(t_s, max(press_duration_s(press), last_s) - 1e-9))
    return float(t_s[min(k, t_s.size - 1)])


def _key_ready_s(stroke: Any, retrigger_m: float, t_s: FloatArray) -> float:
    """Motion start → the key is above its re-trigger depth for the rest of the stroke."""
    k = last_beyond(_f64(stroke.truth_x2_m), float(retrigger_m), False)
    if k < 0:
        return 0.0
    return float(t_s[min(k + 1, t_s.size - 1)])


def _retrigger_m(world: Any) -> float:
    """The world's piano release depth (the re-trigger depth of its keys)."""
    model = getattr(world, "model", None)
    readout = getattr(model, "readout_params", None)
    if callable(readout):
        return float(readout().release_m)
    return DEFAULT_RETRIGGER_M


def _column(trace: Trace, name: str) -> FloatArray:
    values = getattr(trace, name)
    return np.full(len(trace.t_s), np.nan) if values is None else _f64(values)


def _f64(values: Any) -> FloatArray:
    return np.asarray(values, dtype=np.float64)


def make_world(world: dict[str, Any], seed: int) -> Any:
    """The physics World a rig file's `world:` section describes (`preset` plus overrides)."""
    from pianobot.physics.world import World, WorldConfig

    settings = dict(world)
    preset = settings.pop("preset", "default")
    if preset == "linear":
        settings.setdefault("effects", {})  # the study's linear model: no extra effects
    return World(WorldConfig.model_validate(settings), seed)


def build_sim_rig(rig_spec: Any, seed: int, *, world: Any | None = None) -> Rig:
    """Assemble the simulated rig of a RigSpec (kind sim); `world` replaces the physics World."""
    clock = VirtualClock(realtime=bool(rig_spec.realtime))
    faults = SimFaults(**rig_spec.faults.model_dump())
    state = SimState(
        world=world if world is not None else make_world(rig_spec.world, seed),
        clock=clock,
        seed=seed,
        faults=faults,
    )
    arm = SimArm(state, travel_s=lambda a, b: key_change_s(a, b, rig_spec))
    vacuum, keyboard, mocap = SimVacuum(state), SimKeyboard(state), SimMocap(state)

    def before_press(trial: TrialLike, attempt: int) -> None:
        # The keystroke's identity: a redone trial (same id, same attempt) replays exactly.
        state.key = f"{trial.trial_id}#{attempt}"
        state.trial_index = trial.index
        state.truth = None
        state.extra = {}

    def finish(result: KeystrokeResult) -> KeystrokeResult:
        traces = result.traces if state.truth is None else (*result.traces, state.truth)
        return replace(result, traces=traces, extra={**result.extra, **state.extra})

    def clear_stop() -> None:
        state.stop_armed = False

    def prepare(trials: Sequence[TrialLike]) -> None:
        # The block's true trajectories in one vectorised batch; each press then only observes.
        prefetch = getattr(state.world, "prefetch", None)
        if callable(prefetch):
            prefetch([t.press() for t in trials], [t.vacuum_kpa for t in trials])

    settle = rig_spec.settle_s
    station = Station(
        arm, vacuum, keyboard, mocap, clock,
        StationSettings(
            settle_s=settle.between_presses_s,
            after_vacuum_change_s=settle.after_vacuum_change_s,
        ),
        before_press=before_press,
    )
    arm.connect()
    keyboard.start()
    return Rig(
        kind="sim",
        arm=arm,
        vacuum=vacuum,
        keyboard=keyboard,
        mocap=mocap,
        clock=clock,
        station=station,
        finish=finish,
        clear_stop=clear_stop,
        # A paced sim works like the lab, one keystroke at a time: a block worked out ahead would
        # be stored as one part at its end, and a kill would lose minutes of paced trials.
        prepare=None if rig_spec.realtime else prepare,
        description={
            "seed": seed,
            "world": {"preset": "default", **rig_spec.world},
            "faults": rig_spec.faults.model_dump(),
        },
    )
