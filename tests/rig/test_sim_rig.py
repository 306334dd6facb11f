"""The simulated rig: shared world, virtual clock, determinism, fault injection, safe exit."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pytest

from pianobot.physics.trajectory import Press, press_duration_s
from pianobot.plan import key_change_s
from pianobot.rig import Rig, open_rig
from pianobot.rig.clock import VirtualClock, WallClock
from pianobot.rig.errors import ConnectionLost, SafetyStop, SafetyViolation
from pianobot.rig.protocols import Arm, Keyboard, Mocap, Vacuum
from pianobot.spec import RigSpec


@dataclass(frozen=True)
class Event:
    t_s: float
    type: str
    note: int
    velocity: int


@dataclass(frozen=True)
class Stroke:
    t0_s: float
    duration_s: float
    truth_t_s: np.ndarray
    truth_x0_m: np.ndarray
    truth_x1_m: np.ndarray
    truth_x2_m: np.ndarray
    arm_t_s: np.ndarray
    arm_x0_m: np.ndarray
    mocap_t_s: np.ndarray
    mocap_x0_m: np.ndarray
    mocap_x1_m: np.ndarray
    mocap_x2_m: np.ndarray
    midi: tuple[Event, ...]
    key_speed_at_trigger_mps: float
    max_key_travel_m: float


@dataclass
class FakeWorld:
    """A tiny stand-in for physics.World with the same keystroke contract (pure in its inputs)."""

    seed: int = 0
    calls: list[tuple[str, float]] = field(default_factory=list)

    def vacuum_settle_s(self, from_kpa: float, to_kpa: float) -> float:
        return 0.05 * abs(to_kpa - from_kpa)

    def keystroke(self, press: Press, vacuum_kpa: float, *, note: int, t0_s: float, key: str) -> Stroke:
        self.calls.append((key, vacuum_kpa))
        digest = hashlib.sha256(f"{self.seed}|{key}".encode()).digest()
        jitter = digest[0] / 255.0
        duration = press_duration_s(press)
        t = np.linspace(0.0, duration, 50)
        x0 = (press.distance_m + press.depth_m) * np.sin(np.pi * t / duration)
        x2 = np.clip(x0 - press.distance_m, 0.0, 0.01)
        mocap_t = np.arange(0.0, duration, 1 / 120)
        events: tuple[Event, ...] = ()
        speed = press.down_velocity_mps
        if speed > 0.02:
            velocity = int(np.clip(20 + 1000 * speed + 0.3 * abs(vacuum_kpa) + 5 * jitter, 1, 127))
            events = (
                Event(t0_s + 0.3 * duration, "note_on", note, velocity),
                Event(t0_s + 0.8 * duration, "note_off", note, 64),
            )
        return Stroke(
            t0_s, duration, t + t0_s, x0, x0 * 0.9, x2, t + t0_s, x0,
            mocap_t + t0_s, np.interp(mocap_t, t, x0), np.interp(mocap_t, t, x0 * 0.9),
            np.interp(mocap_t, t, x2), events, speed * 0.5 + 0.001 * jitter, float(x2.max()),
        )


@dataclass(frozen=True)
class T:
    trial_id: str
    index: int
    note: int = 60
    vacuum_kpa: float = -20.0
    distance_m: float = 0.01
    down_velocity_mps: float = 0.05

    def press(self) -> Press:
        return Press(self.distance_m, 0.02, self.down_velocity_mps, self.down_velocity_mps, 0.5, 0.0)


def _rig(**faults: Any) -> RigSpec:
    return RigSpec(faults=faults, settle_s={"after_vacuum_change_s": 2.0, "between_presses_s": 0.5})


def test_devices_satisfy_the_protocols_and_share_one_world() -> None:
    world = FakeWorld()
    with open_rig(_rig(), world=world) as rig:
        assert isinstance(rig, Rig) and rig.simulated
        assert isinstance(rig.arm, Arm) and isinstance(rig.vacuum, Vacuum)
        assert isinstance(rig.keyboard, Keyboard) and isinstance(rig.mocap, Mocap)
        result = rig.keystroke(T("a", 0))
        sources = [t.source for t in result.traces]
        assert sources == ["arm", "mocap", "sim-truth"]
        on = [e for e in result.midi if e.type == "note_on"]
        assert len(on) == 1 and result.press.t_start_s <= on[0].t_s <= result.press.t_end_s
        mocap = result.traces[1]
        assert mocap.t_s.min() >= result.press.t_start_s
        # The arm trace and the mocap trace come from the same stroke.
        assert np.nanmax(mocap.x0_m) == pytest.approx(np.max(result.traces[0].x0_m), rel=0.05)
        assert result.extra["max_key_travel_m"] == pytest.approx(0.01)
        assert world.calls == [("a#1", -20.0)]
        description = rig.describe()
        assert description["kind"] == "sim" and description["clock"]["kind"] == "virtual"


def test_only_a_virtual_clock_sim_works_out_blocks_ahead() -> None:
    """A paced (realtime) sim keeps the lab's one-keystroke pace and its store batches (every
    few seconds): a block worked out ahead is stored only at its end, so a kill of a paced run
    would lose up to a block of wall-clock trials."""
    with open_rig(_rig(), world=FakeWorld()) as rig:
        assert rig.batches
    with open_rig(_rig().model_copy(update={"realtime": True}), world=FakeWorld()) as rig:
        assert rig.describe()["clock"]["realtime"]
        assert not rig.batches


def test_virtual_clock_accounts_settles_moves_and_presses_without_sleeping() -> None:
    rig_spec = _rig()
    with open_rig(rig_spec, world=FakeWorld()) as rig:
        t_start = rig.clock.now()
        result = rig.keystroke(T("a", 0))
        duration = press_duration_s(T("a", 0).press())
        # vacuum 0 -> -20: 2 s settle (the arm starts over the first key); press; 0.5 s pause.
        assert result.press.t_start_s - t_start == pytest.approx(2.0)
        assert rig.clock.now() == pytest.approx(t_start + 2.0 + duration + 0.5)
        before = rig.clock.now()
        rig.keystroke(T("b", 1))  # same vacuum, same key: no settle, no move
        assert rig.clock.now() - before == pytest.approx(duration + 0.5)
        before = rig.clock.now()
        rig.keystroke(replace(T("c", 2), note=72))  # another key: lift, traverse, lower
        travel = key_change_s(60, 72, rig_spec)
        assert travel > 0.5
        assert rig.clock.now() - before == pytest.approx(travel + duration + 0.5)


def test_keystrokes_are_deterministic_for_a_key_and_differ_between_attempts() -> None:
    def velocities(attempt: int, seed: int) -> list[int]:
        with open_rig(_rig(midi_loss_prob=0.0), seed=seed, world=FakeWorld(seed)) as rig:
            return [e.velocity for e in rig.keystroke(T("k", 3), attempt).midi]

    assert velocities(1, 0) == velocities(1, 0)
    world = FakeWorld()
    with open_rig(_rig(), world=world) as rig:
        rig.keystroke(T("k", 3), 2)
    assert world.calls[0][0] == "k#2"


def test_connection_drops_every_n_presses_until_reconnected() -> None:
    with open_rig(_rig(drop_connection_every_n_presses=2), world=FakeWorld()) as rig:
        rig.keystroke(T("a", 0))
        with pytest.raises(ConnectionLost):
            rig.keystroke(T("b", 1))
        with pytest.raises(ConnectionLost):
            rig.keystroke(T("b", 1))  # still down
        rig.reconnect()
        assert rig.keystroke(T("b", 1), 2).midi


def test_protective_stop_fires_once_at_its_trial_and_clear_disarms_it() -> None:
    with open_rig(_rig(protective_stop_at_trial=1), world=FakeWorld()) as rig:
        rig.keystroke(T("a", 0))
        with pytest.raises(SafetyStop, match="trial 1"):
            rig.keystroke(T("b", 1))
        assert rig.keystroke(T("b", 1)).midi  # fired once
    with open_rig(_rig(protective_stop_at_trial=1), world=FakeWorld()) as rig:
        rig.clear_stop()  # a resumed run: the operator cleared it
        assert rig.keystroke(T("b", 1)).midi


def test_midi_loss_and_mocap_drop_are_seeded_per_keystroke() -> None:
    def run(seed: int) -> tuple[list[int], int]:
        lost, dropped = [], 0
        with open_rig(_rig(midi_loss_prob=0.5, mocap_drop_prob=0.3), seed=seed, world=FakeWorld()) as rig:
            for i in range(40):
                result = rig.keystroke(T(f"t{i}", i))
                lost.append(len(result.midi))
                dropped += int(np.isnan(result.traces[1].x2_m).sum())
        return lost, dropped

    first, again, other = run(1), run(1), run(2)
    assert first == again and first != other
    counts = first[0]
    assert 0 < sum(counts) < 80 and counts.count(2) < 40
    assert first[1] > 0


def test_exit_makes_safe_even_on_an_exception() -> None:
    vented: list[bool] = []
    with pytest.raises(KeyboardInterrupt), open_rig(_rig(), world=FakeWorld()) as rig:
        original = rig.vacuum.vent

        def vent() -> None:
            vented.append(True)
            original()

        rig.vacuum.vent = vent  # type: ignore[method-assign]
        rig.keystroke(T("a", 0))
        raise KeyboardInterrupt
    assert vented == [True]
    assert not rig.arm.connected  # type: ignore[attr-defined]


def test_keyboard_window_excludes_other_keystrokes_and_buffers_stay_bounded() -> None:
    with open_rig(_rig(), world=FakeWorld()) as rig:
        results = [rig.keystroke(T(f"t{i}", i)) for i in range(200)]
        for result in results:
            assert len(result.midi) == 2
        state = rig.arm.state  # type: ignore[attr-defined]
        assert len(state.midi) < 200 and len(state.mocap) < 200


def test_clocks() -> None:
    clock = VirtualClock(5.0)
    clock.sleep(1.5)
    clock.sleep(-3.0)
    clock.sleep(float("nan"))
    assert clock.now() == 6.5
    wall = WallClock()
    assert 0.0 <= wall.now() < 60.0


@dataclass
class SlowKeyWorld(FakeWorld):
    """A FakeWorld whose key stays down (5 mm) for `linger_s` after the arm is back up."""

    linger_s: float = 0.3

    def keystroke(self, press: Press, vacuum_kpa: float, *, note: int, t0_s: float, key: str) -> Stroke:
        stroke = super().keystroke(press, vacuum_kpa, note=note, t0_s=t0_s, key=key)
        t = np.arange(0.0, stroke.duration_s + self.linger_s, 1e-3)
        arm = np.interp(t, stroke.truth_t_s - t0_s, stroke.truth_x0_m, right=0.0)
        key_x = np.where(t < stroke.duration_s + self.linger_s - 0.05, 0.005, 0.0)
        return replace(stroke, duration_s=float(t[-1]), truth_t_s=t + t0_s, truth_x0_m=arm,
                       truth_x1_m=arm, truth_x2_m=key_x)


def test_press_at_starts_at_the_planned_time_and_returns_when_the_arm_is_up() -> None:
    with open_rig(_rig(), world=FakeWorld()) as rig:
        rig.set_vacuum(-20.0)
        assert rig.move_to_key(60, 0.01) == 0.0  # the arm starts over the first key
        moved = rig.move_to_key(67, 0.01)
        assert moved == pytest.approx(key_change_s(60, 67, _rig()))
        trial = replace(T("a", 0), note=67)
        start = rig.clock.now() + 1.25
        result = rig.press_at(trial, start_at_s=start)
        assert result.press.t_start_s == pytest.approx(start)
        # No settle pause: back as soon as the arm is up; truth and key features as in sweeps.
        assert rig.clock.now() == pytest.approx(start + press_duration_s(trial.press()), abs=1e-3)
        assert [t.source for t in result.traces] == ["arm", "mocap", "sim-truth"]
        assert "max_key_travel_m" in result.extra
        late = rig.press_at(trial, start_at_s=start)  # a start in the past starts at once
        assert late.press.t_start_s == pytest.approx(result.press.t_end_s)


def test_press_at_refuses_a_key_it_does_not_hover_over_or_an_unset_vacuum() -> None:
    world = FakeWorld()
    with open_rig(_rig(), world=world) as rig:
        with pytest.raises(SafetyViolation, match="move_to_key"):
            rig.press_at(T("a", 0))  # nothing positioned yet
        rig.move_to_key(60, 0.01)
        with pytest.raises(SafetyViolation, match="set_vacuum"):
            rig.press_at(T("a", 0))
        rig.set_vacuum(-20.0)
        with pytest.raises(SafetyViolation, match="hovers at note 60"):
            rig.press_at(replace(T("a", 0), note=62))
        assert world.calls == []  # nothing was pressed
        assert rig.press_at(T("a", 0)).midi


def test_a_restrike_waits_for_the_key_to_rise_but_another_key_does_not() -> None:
    with open_rig(_rig(), world=SlowKeyWorld(linger_s=0.3)) as rig:
        rig.set_vacuum(-20.0)
        rig.move_to_key(60, 0.01)
        first = rig.press_at(T("a", 0))
        assert first.press.warnings == ()
        again = rig.press_at(T("b", 1), start_at_s=rig.clock.now())
        # The key stayed below its re-trigger depth for ~0.25 s after the arm was up.
        waited = again.press.t_start_s - first.press.t_end_s
        assert 0.2 < waited < 0.3
        assert "re-strike of note 60 waited" in again.press.warnings[0]
        rig.move_to_key(62, 0.01)
        other = rig.press_at(replace(T("c", 2), note=62))
        assert other.press.warnings == ()
        assert other.press.t_start_s == pytest.approx(again.press.t_end_s + key_change_s(60, 62, _rig()))


def test_keystroke_takes_a_start_time_and_a_settle_override() -> None:
    with open_rig(_rig(), world=FakeWorld()) as rig:
        rig.keystroke(T("a", 0))
        start = rig.clock.now() + 2.0
        result = rig.keystroke(T("b", 1), start_at_s=start, settle_s=0.0)
        assert result.press.t_start_s == pytest.approx(start)
        assert rig.clock.now() == pytest.approx(result.press.t_end_s)


def _naive_window(chunks: list[Any], t_from_s: float, t_to_s: float) -> tuple[np.ndarray, ...]:
    """Every buffered frame inside [t_from, t_to), all chunks concatenated (the reference)."""
    t = np.concatenate([c.t_s for c in chunks] or [np.empty(0)])
    inside = (t >= t_from_s) & (t < t_to_s)
    cols = [np.concatenate([getattr(c, n) for c in chunks] or [np.empty(0)])[inside]
            for n in ("x0_m", "x1_m", "x2_m")]
    return (t[inside], *cols)


def test_mocap_windows_match_the_naive_cut_over_overlapping_chunks_and_a_replaced_buffer() -> None:
    from pianobot.rig.protocols import Trace
    from pianobot.rig.sim import BUFFER_HORIZON_S, SimFaults, SimMocap, SimState

    rng = np.random.default_rng(5)
    state = SimState(world=None, clock=VirtualClock(), seed=0, faults=SimFaults())
    mocap = SimMocap(state)
    everything: list[Trace] = []
    start = 0.0
    for k in range(60):
        # Chunks overlap their neighbours (a key still moving when the next stroke starts),
        # some are empty, all are appended between windows as a sweep does.
        n = 0 if k % 13 == 5 else int(rng.integers(20, 60))
        t = start + np.sort(rng.uniform(0.0, 3.0, n))
        chunk = Trace(t_s=t, x0_m=rng.normal(size=n), x1_m=rng.normal(size=n),
                      x2_m=rng.normal(size=n), source="mocap")
        state.mocap.append(chunk)
        everything.append(chunk)
        if k == 40:
            state.mocap = list(state.mocap)  # someone swaps the list: the spans follow
        if k == 50:
            state.mocap.clear()  # or empties it
            everything = []
        for t_from, t_to in ((start, start + 2.0), (start - 1.5, start + 0.5), (start + 5, start + 6)):
            got = mocap.trace_between(t_from, t_to)
            kept = [c for c in everything if len(c.t_s) and c.t_s[-1] >= t_from - BUFFER_HORIZON_S]
            want = _naive_window(kept, t_from, t_to)
            for a, b in zip((got.t_s, got.x0_m, got.x1_m, got.x2_m), want, strict=True):
                assert np.array_equal(a, b)
        start += 1.7
    # Stale chunks are dropped: the buffer holds about a minute of strokes, not all of them.
    assert all(c.t_s[-1] >= start - 1.7 - BUFFER_HORIZON_S for c in state.mocap)
