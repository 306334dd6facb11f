"""A simulated sweep on an executor: the driver keeps the clock, the workers do the keystrokes.

The driver (this process) holds the run lock, the journal and the store; workers compute (and, on a
local cluster, write their samples part ahead under a temp name: `store.stage_part`).
For each block of trials:

1. a worker simulates the block's distinct keystrokes once and returns when each arm comes back
   and each key is ready again (`sim_blocks.keystroke_times`);
2. the driver runs the block's *timeline*: the real station, faults, retries and stop control on
   a rig whose world only knows those times (`TimingWorld`). This is cheap and yields the state
   the next block starts from, so the timeline runs ahead of the workers;
3. a worker builds a fresh simulated rig in the block's start state, replays the observations of
   earlier keystrokes that can still reach into the block, and runs the block exactly as one
   process would (`Runner.run_block`), returning its records (trial rows, samples, MIDI). The
   task goes to the worker that did step 1 for the block, which kept the block's true
   trajectories: its rig takes them (`World.adopt`) instead of simulating them again;
4. the driver checks that the worker ended where the timeline did, then publishes the records in
   plan order to the store sink, the progress bar and any subscriber, one part per block.

So the trials, their samples and MIDI, retries, faults and stops are the same as a sweep in one
process with the same seed, and exactly-once holds as before: only the driver commits parts (a
staged one by renaming it into place) and journals them. A kill -9 of the driver loses the blocks
in flight; resume redoes them and sweeps the staged parts they left.
"""

from __future__ import annotations

import sys
from collections import OrderedDict
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

from pianobot.executor import Executor
from pianobot.rig import Rig, TrialLike, open_rig
from pianobot.rig.errors import DeviceUnavailable
from pianobot.run.records import (
    BlockEnded,
    Record,
    RunEnded,
    RunStarted,
    Subscriber,
    TrialDone,
    TrialRetried,
    TrialStarted,
    TrialStopped,
)
from pianobot.run.rows import NOTE_ON_LOST, TrialData, midi_table, samples_table, trials_table
from pianobot.run.runner import RetryPolicy, Runner, SessionResult
from pianobot.run.signals import StopControl
from pianobot.store import StagedPart, encode_part, stage_part


@dataclass(frozen=True)
class SweepSetup:
    """What a worker needs to build the same simulated rig as the driver."""

    run_id: str
    rig_spec: Any  # pianobot.spec.RigSpec
    seed: int
    world: Any | None  # a World replacing the rig file's (tests, benchmarks)
    record: tuple[str, ...]
    motion: bool
    retry: RetryPolicy
    clock_offset_s: float
    # The run's samples folder when the workers share this file system (a local cluster): a
    # worker then writes its samples part there itself (`stage_part`), the driver only renames it.
    stage_dir: str | None = None


@dataclass(frozen=True)
class BlockTask:
    """One block for a worker: its trials, start state and the keystrokes to replay first."""

    setup: SweepSetup
    trials: tuple[TrialLike, ...]
    start: Any  # sim_blocks.SimSnapshot
    prelude: tuple[Any, ...]  # sim_blocks.KeystrokeCall
    worker: str | None = None  # where the block's truths are kept (`block_times`)
    attempts: tuple[tuple[str, int], ...] = ()  # first attempts of keys pressed again


@dataclass(frozen=True)
class BlockResult:
    """What a worker hands back: the block's records in order and the state it ended in."""

    records: list[Record]
    outcome: tuple[str, str] | None
    end: Any  # sim_blocks.SimSnapshot
    parts: dict[str, bytes | StagedPart]  # the block's Parquet parts, encoded or staged


def block_times(task: tuple[SweepSetup, tuple[Any, ...]]) -> tuple[dict[Any, Any], str | None]:
    """Worker: when arm and key are ready after each distinct keystroke of a block, and the
    address of this worker (None outside a cluster), which keeps the block's truths for its run
    (`run_block` there simulates nothing again)."""
    from pianobot.rig import sim_blocks

    setup, keystrokes = task
    kept: dict[Any, Any] = {}
    times = sim_blocks.keystroke_times(_world(setup), list(keystrokes), kept)
    _KEPT[(setup.run_id, keystrokes)] = kept
    while len(_KEPT) > KEPT_BLOCKS:
        _KEPT.popitem(last=False)
    return times, _worker_address()


def run_block(task: BlockTask) -> BlockResult:
    """Worker: run one block from its start state, as a sweep in one process would."""
    from pianobot.rig import sim_blocks

    setup = task.setup
    records: list[Record] = []

    def keep(record: Record) -> None:
        records.append(record)

    world = _world(setup)
    with open_rig(setup.rig_spec, seed=setup.seed, world=world) as rig:
        sim_blocks.restore(rig, task.start)
        sim_blocks.replay(rig, task.prelude)
        runner = Runner(rig, subscribers=[keep], retry=setup.retry, record=setup.record,
                        clock_offset_s=setup.clock_offset_s, motion=setup.motion)
        kept = _KEPT.pop((setup.run_id, _keystrokes(task.trials)), None)
        if kept:  # this worker worked out the block's times: its truths are simulated already
            world.adopt(kept)
        rig.prepare(task.trials)
        counts = {"executed": 0, "silent": 0, "retries": 0, "done": 0}
        outcome = runner.run_block(task.trials, counts, dict(task.attempts))
        end = sim_blocks.snapshot(rig)
    # The heavy part of storing, encoding the Parquet parts, happens here; the driver only
    # writes the bytes (or renames the samples part staged here) and journals them. The records
    # go back with their trial rows only.
    data = [r.data for r in records if isinstance(r, TrialDone)]
    parts: dict[str, bytes | StagedPart] = {}
    if data:
        tables = {"trials": trials_table(data), "samples": samples_table(data),
                  "midi": midi_table(data)}
        for name, table in tables.items():
            if table is None or not table.num_rows:
                continue
            encoded = encode_part(table, name, setup.run_id)
            staged = name == "samples" and setup.stage_dir is not None
            parts[name] = stage_part(str(setup.stage_dir), encoded, table.num_rows) if staged else encoded
    slim = [TrialDone(TrialData(row=r.data.row), r.lab_time_s) if isinstance(r, TrialDone) else r
            for r in records]
    return BlockResult(slim, outcome, end, parts)


_WORLDS: dict[tuple[str, int], Any] = {}
#: Truths `block_times` simulated on this worker, by (run, block keystrokes), until the block runs
#: here; the oldest go first (a block that ran elsewhere, or stopped early, is never asked for).
_KEPT: OrderedDict[tuple[str, tuple[Any, ...]], dict[Any, Any]] = OrderedDict()
KEPT_BLOCKS = 4


def _keystrokes(trials: Sequence[TrialLike]) -> tuple[tuple[Any, float], ...]:
    """A block's keystrokes as (press, vacuum): what its times are worked out for, and the key
    its kept truths are found by."""
    return tuple((t.press(), t.vacuum_kpa) for t in trials)


def _worker_address() -> str | None:
    """This Dask worker's address; None in a process that is not one (checked without importing
    distributed, which a serial sweep never loads)."""
    distributed = sys.modules.get("distributed")
    if distributed is None:
        return None
    try:
        return str(distributed.get_worker().address)
    except ValueError:  # distributed is loaded, but this is not a worker
        return None


def _world(setup: SweepSetup) -> Any:
    """The setup's world, built once per worker process (its kernels load once, too)."""
    if setup.world is not None:
        return setup.world
    from pianobot.rig import sim_blocks

    key = (setup.rig_spec.model_dump_json(), setup.seed)
    if key not in _WORLDS:
        _WORLDS.clear()  # one sweep at a time per process
        _KEPT.clear()
        _WORLDS[key] = sim_blocks.world_for(setup.rig_spec, setup.seed)
    return _WORLDS[key]


@dataclass
class _Timeline:
    """The driver's side: the timeline rig and runner, and what the workers must reproduce."""

    rig: Rig
    runner: Runner
    world: Any  # sim_blocks.TimingWorld
    expected_end: dict[int, Any] = field(default_factory=dict)
    outcome: tuple[str, str] | None = None
    started: list[str] = field(default_factory=list)


def run_parallel(
    rig: Rig,
    setup: SweepSetup,
    executor: Executor,
    *,
    run_id: str,
    trials: Sequence[TrialLike],
    planned: int,
    done: int,
    block_trials: int,
    subscribers: Sequence[Subscriber],
    control: StopControl,
) -> SessionResult:
    """Run `trials` in blocks on `executor`, publishing records to `subscribers` in plan order."""
    from pianobot.rig import sim_blocks

    blocks = [tuple(trials[i : i + block_trials]) for i in range(0, len(trials), max(1, block_trials))]

    def publish(record: Record) -> None:
        for subscriber in subscribers:
            subscriber(record)

    publish(RunStarted(run_id, planned=planned, done=done, todo=len(trials), resumed=done > 0,
                       blocks=True))
    counts = {"executed": 0, "silent": 0, "retries": 0, "done": done}
    status, reason = "completed", None
    timing_world = sim_blocks.TimingWorld(_world(setup), {})
    with open_rig(setup.rig_spec, seed=setup.seed, world=timing_world) as timeline_rig:
        started: list[str] = []

        def note_start(record: Record) -> None:
            if isinstance(record, TrialStarted):
                started.append(record.trial_id)

        timeline = _Timeline(
            timeline_rig,
            Runner(timeline_rig, retry=setup.retry, record=(), control=control,
                   clock_offset_s=setup.clock_offset_s, motion=setup.motion,
                   subscribers=[note_start]),
            timing_world,
            started=started,
        )
        sim_blocks.restore(timeline_rig, sim_blocks.snapshot(rig))
        by_id = {t.trial_id: t for t in trials}
        attempts: dict[str, int] = {}
        try:
            while blocks:
                redo: list[tuple[str, int]] = []
                outcome = _run_pass(timeline, setup, executor, blocks, attempts, publish, counts, redo)
                if outcome is not None:
                    status, reason = outcome
                    break
                # Keys whose note-on was lost are pressed again, in plan order (`Runner.run`).
                again = [by_id[trial_id] for trial_id, _ in redo]
                blocks = [tuple(again[i : i + block_trials])
                          for i in range(0, len(again), max(1, block_trials))]
                attempts = dict(redo)
        except KeyboardInterrupt as exc:
            status, reason = "interrupted", str(exc) or "interrupted: stopped at once, rig made safe"
        except DeviceUnavailable as exc:
            status, reason = "failed", f"device unavailable: {exc}"
        finally:
            control.shutting_down = True
        lab_time_s = timeline_rig.clock.now() + setup.clock_offset_s
    publish(RunEnded(status, reason, lab_time_s, counts["done"], counts["retries"]))
    return SessionResult(status=status, reason=reason, done=counts["done"],
                         executed=counts["executed"], silent=counts["silent"],
                         retries=counts["retries"], lab_time_s=lab_time_s)


def _run_pass(
    timeline: _Timeline,
    setup: SweepSetup,
    executor: Executor,
    blocks: list[tuple[TrialLike, ...]],
    attempts: dict[str, int],
    publish: Subscriber,
    counts: dict[str, int],
    redo: list[tuple[str, int]],
) -> tuple[str, str] | None:
    """Run `blocks` on the workers, publishing their records in plan order; (status, reason) if
    the run must end. Trials to press again are added to `redo` as (trial id, next attempt)."""
    times = executor.imap(block_times, ((setup, _keystrokes(b)) for b in blocks), ahead=2)
    tasks = _tasks(timeline, setup, blocks, times, attempts)
    # Each block runs where its times were worked out, if that worker is free to: its truths
    # are kept there.
    for number, result in enumerate(executor.imap(run_block, tasks, where=lambda t: t.worker)):
        if result.end != timeline.expected_end.pop(number):
            raise RuntimeError(f"block {number} of run {setup.run_id} ended in another state on "
                               "its worker than in the driver's timeline")
        # A stop ends the block after its last keystroke: the part goes first.
        stops = [r for r in result.records if isinstance(r, TrialStopped)]
        for record in result.records:
            if not isinstance(record, TrialStopped):
                _count(record, counts)
                publish(record)
            if isinstance(record, TrialRetried) and record.error == NOTE_ON_LOST:
                redo.append((record.trial_id, record.attempt + 1))
        publish(BlockEnded(sum(isinstance(r, TrialDone) for r in result.records),
                           result.end.clock_s + setup.clock_offset_s,
                           result.parts if "trials" in result.parts else None))
        for record in stops:
            publish(record)
        if result.outcome is not None:
            return result.outcome
    return timeline.outcome  # stopped before any trial of a block ran, or None


def _tasks(
    timeline: _Timeline,
    setup: SweepSetup,
    blocks: list[tuple[TrialLike, ...]],
    times: Iterator[Any],
    attempts: dict[str, int],
) -> Iterator[BlockTask]:
    """Run each block's timeline and yield the worker's task for it (lazily, as workers free up)."""
    from pianobot.rig import sim_blocks

    world, rig = timeline.world, timeline.rig
    for number, block in enumerate(blocks):
        found, worker = next(times)
        world.times.update(found)
        start = sim_blocks.snapshot(rig)
        reach = start.clock_s
        prelude = tuple(c for c in world.calls if c.end_s > reach)
        world.calls = list(prelude)  # older keystrokes can no longer reach a window
        timeline.started.clear()
        scratch = {"executed": 0, "silent": 0, "retries": 0, "done": 0}
        timeline.outcome = timeline.runner.run_block(block, scratch, attempts)
        started = set(timeline.started)
        ran = tuple(t for t in block if t.trial_id in started)
        if not ran:
            return
        timeline.expected_end[number] = sim_blocks.snapshot(rig)
        again = tuple((t.trial_id, attempts[t.trial_id]) for t in ran if t.trial_id in attempts)
        yield BlockTask(setup, ran, start, prelude, worker, again)
        if timeline.outcome is not None:
            return


def _count(record: Record, counts: dict[str, int]) -> None:
    if isinstance(record, TrialDone):
        counts["executed"] += 1
        if record.status != "failed":
            counts["done"] += 1
        if record.status == "silent":
            counts["silent"] += 1
    elif isinstance(record, TrialRetried):
        counts["retries"] += 1
