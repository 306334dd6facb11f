"""`run_sweep`: a spec file in, a run folder out — validate, persist the plan, run, compact.

Everything that can be wrong with the input is checked before the run folder is made, so a bad
spec leaves nothing behind. The plan is on disk before the arm moves. A resume (`resume=RUN_ID`)
re-reads the same spec (its sha256 must match), skips every trial whose data is on disk, redoes
the one in flight, and continues the run clock where it stopped.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from contextlib import ExitStack
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from pianobot.errors import InputError, check_seed
from pianobot.executor import IN_PROCESS, Executor, ExecutorSettings, open_executor
from pianobot.plan import (
    DEFAULT_MAX_TRIALS,
    PlanSummary,
    Trial,
    check_envelope,
    expand,
    plan_frame,
    summarize,
)
from pianobot.plan.approach import apply_approach
from pianobot.rig import Rig, open_rig
from pianobot.rig.errors import DeviceUnavailable
from pianobot.run.parallel import SweepSetup, run_parallel
from pianobot.run.progress import ProgressBar, stage
from pianobot.run.records import Subscriber
from pianobot.run.resume import (
    check_same_rig,
    record_rig_session,
    record_software_session,
    refuse_damaged,
)
from pianobot.run.runner import BLOCK_TRIALS, RetryPolicy, Runner, SessionResult
from pianobot.run.signals import SignalHandlers, StopControl
from pianobot.run.sink import StoreSink
from pianobot.spec import (
    ExperimentSpec,
    RigSpec,
    load_rig,
    load_rig_for,
    load_spec,
    resolved_spec_dict,
    spec_sha256,
)
from pianobot.store import (
    Run,
    RunLocked,
    RunWriter,
    check_data_dir,
    load_run,
    read_journal,
    summarize_run,
)
from pianobot.store.tables import read_run_table, trial_status_counts

BATCH_TRIALS = 50  # trials per part on a rig that runs keystrokes one at a time


@dataclass(frozen=True)
class PreparedSweep:
    """A validated spec with its rig and plan, before anything is written or moved."""

    spec_path: Path
    spec: ExperimentSpec
    rig: RigSpec
    trials: list[Trial]
    spec_text: str
    spec_sha256: str
    seed: int
    rig_path: Path | None = None  # a rig file given instead of the spec's own


@dataclass(frozen=True)
class RunOutcome:
    """How a sweep (or a resumed session of it) ended, and where its data is."""

    run_id: str
    path: Path
    status: str  # completed | stopped | interrupted | failed
    reason: str | None
    trials: int  # completed trials (ok + silent) over the whole run
    planned: int
    silent: int  # over the whole run
    failed: int
    retries: int  # in this session
    executed: int  # keystrokes recorded in this session
    lab_time_s: float
    resumed: bool
    warnings: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["path"] = str(self.path)
        return data


def prepare_sweep(
    spec_path: Path, *, seed: int | None = None, rig_path: Path | None = None,
    max_trials: int = DEFAULT_MAX_TRIALS,
) -> PreparedSweep:
    """Load and check a spec and its rig and expand the plan; raises InputError, writes nothing.

    `rig_path` replaces the rig file the spec names (e.g. the faulty sim rig for a drill);
    a plan of more than `max_trials` trials is refused before it is built.
    """
    check_seed(seed)
    path = Path(spec_path)
    spec = load_spec(path, rig=rig_path)
    rig = load_rig_for(spec) if rig_path is None else load_rig(rig_path)
    trials = apply_approach(spec, expand(spec, rig, max_trials=max_trials), rig)
    if not trials:
        raise InputError("the sweep has no trials", f"{path}: sweep")
    text = path.read_text(encoding="utf-8")
    return PreparedSweep(
        spec_path=path,
        spec=spec,
        rig=rig,
        trials=trials,
        spec_text=text,
        spec_sha256=spec_sha256(path),
        seed=int(rig.seed if seed is None else seed),
        rig_path=rig_path,
    )


def run_sweep(
    spec_path: Path | None,
    *,
    data_dir: Path,
    resume: str | None = None,
    seed: int | None = None,
    rig_path: Path | None = None,
    progress: bool = True,
    subscribers: Iterable[Subscriber] = (),
    control: StopControl | None = None,
    batch_trials: int | None = None,
    batch_s: float = 2.0,
    world: Any | None = None,
    max_trials: int = DEFAULT_MAX_TRIALS,
    rig_override: bool = False,
    executor: ExecutorSettings | None = None,
) -> RunOutcome:
    """Run a sweep on its rig into a new run folder, or resume run `resume`.

    Args:
        spec_path: the spec file (optional when resuming: the run remembers it).
        data_dir: dataset folder; the run lands in `data_dir/runs/<run_id>/`.
        resume: a run id (or unique prefix) to continue.
        seed: overrides the rig's seed for a new run (the simulated world's noise and faults).
        rig_path: a rig file instead of the one the spec names (a resume reuses the run's).
        progress: draw a progress bar on stderr.
        subscribers: more record consumers (e.g. a test collector).
        control: a stop control (tests); by default SIGINT/SIGTERM drive one.
        batch_trials, batch_s: part batching (a kill loses at most one batch, redone on resume).
            On a batching rig (the simulator) a batch is also the block of trials simulated
            together; default 50 trials, 128 on a batching rig.
        world: a physics World for the sim rig instead of the rig file's (tests, benchmarks).
        max_trials: refuse a plan with more trials (a resume allows the run's own plan).
        rig_override: let a resume run on another rig than the run started with (recorded).
        executor: where a simulated sweep's blocks run (`--workers`, `--scheduler`; default: this
            process for small sweeps, else a local cluster sized to the machine). The driver
            (this process) keeps the run lock, the journal and every write.

    Raises:
        InputError: bad spec, unknown run, a spec that changed since the run started, a damaged
            run (RunDamaged), another rig on resume without `rig_override`.
    """
    writer: RunWriter | None = None
    done_ids: set[str] = set()
    check_data_dir(Path(data_dir))
    if resume is not None:
        writer, prepared, done_ids = _reopen(Path(data_dir), resume, spec_path, seed, rig_path,
                                             max_trials=max_trials, rig_override=rig_override)
    else:
        if spec_path is None:
            raise InputError("give a spec file (or --resume RUN_ID)", "SPEC")
        with stage(progress, "expanding the plan"):
            prepared = prepare_sweep(spec_path, seed=seed, rig_path=rig_path, max_trials=max_trials)
    with ExitStack() as stack:
        if writer is not None:
            stack.enter_context(writer)
            if not any(t.trial_id not in done_ids for t in prepared.trials):
                _note_resume(writer, writer.meta, done_ids)
                writer.finish("completed", None)
                return _outcome(writer, None, resumed=True)
        # The rig opens before the run folder exists: an unreachable device leaves nothing.
        try:
            with stage(progress, "opening the rig"):
                rig = stack.enter_context(open_rig(prepared.rig, seed=prepared.seed, world=world))
        except DeviceUnavailable as exc:
            raise InputError(f"device unavailable: {exc}", "rig") from None
        # So does the executor: an unreachable --scheduler used to leave a failed run behind.
        todo = sum(1 for t in prepared.trials if t.trial_id not in done_ids)
        pool = _executor(rig, executor, todo)
        if writer is None:
            writer = stack.enter_context(_create(Path(data_dir), prepared))
        return _session(
            writer, rig, prepared, done_ids,
            resumed=resume is not None, progress=progress, subscribers=list(subscribers),
            control=control or StopControl(), batch_trials=batch_trials, batch_s=batch_s,
            pool=pool, world=world,
        )
    raise AssertionError("unreachable")  # for type checkers: the with block always returns


def _create(data_dir: Path, prepared: PreparedSweep) -> RunWriter:
    spec = prepared.spec
    meta = {
        "spec": {
            "path": str(prepared.spec_path.resolve()),
            "text": prepared.spec_text,
            "resolved": resolved_spec_dict(spec),
        },
        "spec_sha256": prepared.spec_sha256,
        "seed": prepared.seed,
        "finger": spec.finger,
        "record": list(spec.record),
        "rig": {
            "file": str(prepared.rig_path.resolve()) if prepared.rig_path else spec.rig,
            "override": prepared.rig_path is not None,
            "spec": prepared.rig.model_dump(mode="json"),
        },
        "sessions": 1,
        "lab_time_s": 0.0,
    }
    return RunWriter.create(
        data_dir, name=spec.name, kind="sweep", meta=meta, plan=plan_frame(prepared.trials)
    )


def _same_resolved_spec(path: Path, meta: dict[str, Any]) -> bool:
    """Whether the spec at `path` resolves to what the run recorded (comments and layout aside)."""
    recorded = (meta.get("spec") or {}).get("resolved")
    if recorded is None:
        return False
    try:
        return bool(json.loads(json.dumps(resolved_spec_dict(load_spec(path)), default=str)) == recorded)
    except InputError:
        return False


def _reopen(
    data_dir: Path, run_id: str, spec_path: Path | None, seed: int | None, rig_path: Path | None,
    *, max_trials: int, rig_override: bool,
) -> tuple[RunWriter, PreparedSweep, set[str]]:
    """Open a run to resume: intact, same spec (by sha256), same plan and rig, the trials on disk."""
    run = load_run(run_id, data_dir, check=False)
    refuse_damaged(run.paths)  # before anything else reads it, and long before the arm moves
    meta = run.meta
    if meta.get("kind") != "sweep":
        raise InputError(f"run {run.run_id} is a {meta.get('kind')!r} run, not a sweep", "--resume")
    recorded = Path(str(meta.get("spec", {}).get("path", "")))
    path = Path(spec_path) if spec_path is not None else recorded
    if not path.is_file():
        raise InputError(f"the run's spec file {path} is gone; give the spec: pianobot sweep SPEC --resume {run.run_id}", "SPEC")
    if spec_sha256(path) != meta.get("spec_sha256") and not _same_resolved_spec(path, meta):
        # Only a change of what the spec says refuses the resume: an edited comment, a reordered
        # key or `5e-2` for `0.05` plan the same trials (the plan check below makes sure).
        raise InputError(
            f"{path} differs from the spec run {run.run_id} started with (its settings changed); "
            "restore it, or start a new run",
            "--resume",
        )
    if seed is not None and seed != meta.get("seed"):
        raise InputError(f"run {run.run_id} uses seed {meta.get('seed')}, not {seed}", "--seed")
    rig_meta = meta.get("rig") or {}
    if rig_path is None and rig_meta.get("override"):
        rig_path = Path(str(rig_meta.get("file")))
    planned = int(meta.get("trials_planned") or 0)
    prepared = prepare_sweep(path, seed=int(meta.get("seed", 0)), rig_path=rig_path,
                             max_trials=max(max_trials, planned))
    rig_label = str(rig_path) if rig_path is not None else prepared.spec.rig
    rig_changed = check_same_rig(meta, prepared.rig, rig_label, override=rig_override)
    planned_ids = list(run.plan["trial_id"]) if len(run.plan) else []
    if planned_ids != [t.trial_id for t in prepared.trials]:
        raise InputError(f"the plan of {path} no longer matches run {run.run_id}'s plan.parquet", "--resume")
    try:
        writer = RunWriter.reopen(data_dir, run.run_id)
    except RunLocked as exc:
        raise InputError(str(exc), "--resume") from None
    if rig_changed:
        record_rig_session(writer, prepared.rig, rig_label, int(meta.get("sessions", 1)) + 1)
    record_software_session(writer, int(meta.get("sessions", 1)) + 1)
    trials = read_run_table(writer.paths, "trials", columns=["trial_id", "status"]).to_pydict()
    done_ids = {
        t for t, s in zip(trials["trial_id"], trials["status"], strict=True) if s in ("ok", "silent")
    }
    return writer, prepared, done_ids


def _session(
    writer: RunWriter,
    rig: Rig,
    prepared: PreparedSweep,
    done_ids: set[str],
    *,
    resumed: bool,
    progress: bool,
    subscribers: list[Subscriber],
    control: StopControl,
    batch_trials: int | None,
    batch_s: float,
    pool: Executor,
    world: Any | None,
) -> RunOutcome:
    """Run the trials not yet done on an open rig; the run folder records how it ended."""
    meta = writer.meta
    todo = [t for t in prepared.trials if t.trial_id not in done_ids]
    if resumed:
        _note_resume(writer, meta, done_ids)
    writer.update_meta(rig={**meta.get("rig", {}), "description": rig.describe(),
                            "warnings": list(rig.warnings)})
    if batch_trials is None:
        batch_trials = BLOCK_TRIALS if rig.batches else BATCH_TRIALS
    sink = StoreSink(writer, batch_trials=batch_trials, batch_s=batch_s)
    retry = prepared.rig.retry
    with ExitStack() as stack:
        stack.enter_context(SignalHandlers(control))
        bar = stack.enter_context(ProgressBar()) if progress else None
        try:
            if any(i.get("kind") == "safety_stop" for i in meta.get("interruptions", [])):
                # Resuming a run a protective stop ended means the operator cleared it.
                rig.clear_stop()
                writer.journal("stop_cleared")
            everyone: list[Subscriber] = [sink, *([bar] if bar is not None else []), *subscribers]
            policy = RetryPolicy(retry.max_attempts, retry.backoff_s, retry.backoff_factor)
            offset_s = float(meta.get("lab_time_s") or 0.0)
            fast = prepared.spec.approach == "fast"
            writer.update_meta(executor=pool.describe())
            if pool.kind != "in-process":
                # Workers of a local cluster share this file system: they write the samples
                # parts themselves (the driver's writing bounded a sweep's speed-up on a cluster).
                local = pool.kind == "local-cluster"
                setup = SweepSetup(writer.run_id, prepared.rig, prepared.seed, world,
                                   tuple(prepared.spec.record), fast, policy, offset_s,
                                   stage_dir=str(writer.paths.samples) if local else None)
                result = run_parallel(
                    rig, setup, pool, run_id=writer.run_id, trials=todo,
                    planned=len(prepared.trials), done=len(done_ids), block_trials=batch_trials,
                    subscribers=everyone, control=control,
                )
            else:
                runner = Runner(
                    rig, subscribers=everyone, retry=policy, record=prepared.spec.record,
                    control=control, clock_offset_s=offset_s, motion=fast, block_trials=batch_trials,
                )
                result = runner.run(
                    writer.run_id, todo, planned=len(prepared.trials), done=len(done_ids)
                )
        except BaseException as exc:
            # A bug, a device failure or a Ctrl-C outside the trial loop: keep what was
            # measured and say why the run ended.
            _flush_quietly(sink)
            status = "interrupted" if isinstance(exc, KeyboardInterrupt) else "failed"
            writer.finish(status, f"{type(exc).__name__}: {exc}")
            raise
    _record_end(writer, result)
    writer.finish(result.status, result.reason, lab_time_s=result.lab_time_s)
    return _outcome(writer, result, resumed=resumed, warnings=rig.warnings)


# Measured per simulated trial with every stream stored (one core): what the executor weighs
# against the cost of starting worker processes.
SIM_TRIAL_COST_S = 3e-3


def _executor(rig: Rig, settings: ExecutorSettings | None, todo: int) -> Executor:
    """Where the keystrokes run: a real rig presses one key at a time, here; the simulator's
    blocks go to the executor the settings ask for (in this process for small sweeps)."""
    if not rig.batches:
        return IN_PROCESS
    return open_executor(settings, work_s=todo * SIM_TRIAL_COST_S)


def _note_resume(writer: RunWriter, meta: dict[str, Any], done_ids: set[str]) -> None:
    """Journal the resume, and a crash if the last session never closed the run."""
    if meta.get("status") == "running":
        writer.add_interruption("crash", reason="the process ended without closing the run (killed?)")
    journalled = {
        e.get("trial_id") for e in read_journal(writer.paths.journal) if e.get("event") in ("done", "recovered")
    }
    for trial_id in sorted(done_ids - journalled):
        # Its part landed but the process died before journalling `done`.
        writer.journal("recovered", trial_id=trial_id)
    writer.update_meta(
        status="running", reason=None, end_utc=None, sessions=int(meta.get("sessions", 1)) + 1,
        resumed_pid=os.getpid(),
    )


def _record_end(writer: RunWriter, result: SessionResult) -> None:
    if result.status == "stopped":
        writer.add_interruption("safety_stop", reason=result.reason)
    elif result.status == "interrupted":
        writer.add_interruption("signal", reason=result.reason)


def _flush_quietly(sink: StoreSink) -> None:
    try:
        sink.flush()
    except Exception:  # the original error matters more than a failed last write
        pass


def _outcome(
    writer: RunWriter, result: SessionResult | None, *, resumed: bool, warnings: tuple[str, ...] = ()
) -> RunOutcome:
    summary = summarize_run(Run(run_id=writer.run_id, path=writer.path))
    counts = trial_status_counts(writer.paths)
    return RunOutcome(
        run_id=writer.run_id,
        path=writer.path,
        status=summary.status,
        reason=summary.reason,
        trials=summary.trials_done,
        planned=summary.trials_planned or 0,
        silent=counts["silent"],
        failed=counts["failed"],
        retries=0 if result is None else result.retries,
        executed=0 if result is None else result.executed,
        lab_time_s=summary.lab_time_s,
        resumed=resumed,
        warnings=list(warnings),
    )


def dry_run(
    spec_path: Path, *, rig_path: Path | None = None, max_trials: int = DEFAULT_MAX_TRIALS
) -> PlanSummary:
    """The plan of a spec without running it: count, coverage, lab time, every violation.

    Spec-level problems (unknown key, wrong type, a written value outside the envelope, a plan
    above `max_trials`) raise InputError; trial-level envelope violations are listed in the
    summary, not raised.
    """
    spec = load_spec(Path(spec_path), rig=rig_path)
    rig = load_rig_for(spec) if rig_path is None else load_rig(rig_path)
    trials = apply_approach(spec, expand(spec, max_trials=max_trials), rig)
    label = spec.rig if rig_path is None else str(rig_path)
    violations = check_envelope(trials, spec.finger, rig, rig_label=label)
    return summarize(spec, trials, violations, rig, rig_label=label)  # the rig in use, not the spec's
