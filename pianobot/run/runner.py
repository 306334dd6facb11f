"""The runner: executes planned trials on a rig and publishes what happens.

Per trial: publish `TrialStarted`, run the keystroke; on a dropped connection wait (backoff on
the rig's clock, virtual for the sim), reconnect and try again up to `max_attempts`, publishing
`TrialRetried` each time; then publish `TrialDone` (ok | silent, or failed once retries are
exhausted or the target was refused). A protective stop is never retried: the trial is reported
as `TrialStopped` and the run ends with status `stopped`. A stop request (first Ctrl-C/SIGTERM)
ends the run after the current trial with status `interrupted`.

A keystroke whose note-on was lost on the way (the piano's note-off came without it) is stored
as failed, without its samples and MIDI, and `TrialRetried` says it will be pressed again: once
every trial has run, the session presses those keys again (`redo`), up to `max_attempts` in all.
Deciding this after the fact, not inside the trial, keeps the keystrokes before it as planned:
a parallel sweep's timeline, which knows no MIDI, stays the one the workers run.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace

from pianobot.plan.trial import SEQUENCE_COLUMNS
from pianobot.rig import Rig, TrialLike
from pianobot.rig.errors import ConnectionLost, DeviceUnavailable, SafetyStop, SafetyViolation
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
from pianobot.run.rows import TrialData, failed_trial, parameters_of, read_keystroke
from pianobot.run.signals import StopControl

# Trials a batching (simulated) rig works out at once: enough for the vectorised simulator to
# fill its SIMD lanes with keystrokes of similar length, few enough that a block's true
# trajectories stay a few tens of MB and a kill redoes little.
BLOCK_TRIALS = 128


@dataclass(frozen=True)
class RetryPolicy:
    """Bounded retries with exponential backoff: wait backoff_s · factor^(n-1) before retry n."""

    max_attempts: int = 3
    backoff_s: float = 1.0
    backoff_factor: float = 2.0

    def backoff_before(self, attempt: int) -> float:
        """The wait before `attempt` (2, 3, ...)."""
        return self.backoff_s * self.backoff_factor ** max(0, attempt - 2)


@dataclass(frozen=True)
class SessionResult:
    """How one session of the runner ended."""

    status: str  # completed | stopped | interrupted | failed
    reason: str | None
    done: int  # trials completed over the whole run (earlier sessions included)
    executed: int  # keystrokes recorded in this session (ok, silent or failed)
    silent: int  # silent keystrokes in this session
    retries: int
    lab_time_s: float


class Runner:
    """Runs trials on a rig, publishing records to subscribers."""

    def __init__(
        self,
        rig: Rig,
        *,
        subscribers: Iterable[Subscriber] = (),
        retry: RetryPolicy | None = None,
        record: Sequence[str] = ("midi", "arm", "mocap"),
        control: StopControl | None = None,
        clock_offset_s: float = 0.0,
        motion: bool = False,
        block_trials: int = BLOCK_TRIALS,
    ) -> None:
        self.rig = rig
        self.block_trials = block_trials  # trials a batching rig prepares at once
        self.motion = motion  # keep the commanded fast moves in the trials rows
        self.subscribers = list(subscribers)
        self.retry = retry or RetryPolicy()
        self.record = tuple(record)
        self.control = control or StopControl()
        self.clock_offset_s = clock_offset_s
        self.redo: list[tuple[TrialLike, int]] = []  # (trial, next attempt): note-ons lost

    def now(self) -> float:
        """The run clock: the rig's clock plus the lab time of earlier sessions."""
        return self.rig.clock.now() + self.clock_offset_s

    def publish(self, record: Record) -> None:
        for subscriber in self.subscribers:
            subscriber(record)

    def run(self, run_id: str, trials: Sequence[TrialLike], *, planned: int, done: int = 0) -> SessionResult:
        """Execute `trials` in order; `done` trials of `planned` were completed before.

        On a rig that batches (the simulator) the trials go in blocks: the rig prepares a
        block at once (its physics in one vectorised batch), then each trial runs as on any rig
        (faults, retries, records), and a `BlockEnded` lets the store write the block as a part.
        """
        blocked = self.rig.batches
        self.publish(RunStarted(run_id, planned=planned, done=done, todo=len(trials),
                                resumed=done > 0, blocks=blocked,
                                warnings=self.rig.warnings))
        counts = {"executed": 0, "silent": 0, "retries": 0, "done": done}
        status, reason = "completed", None
        try:
            todo: Sequence[TrialLike] = trials
            attempts: dict[str, int] = {}
            while todo:
                outcome = self._run_pass(todo, counts, attempts)
                if outcome is not None:
                    status, reason = outcome
                    break
                # Keys whose note-on was lost are pressed again, in plan order.
                todo, attempts = [t for t, _ in self.redo], {t.trial_id: a for t, a in self.redo}
                self.redo = []
        except KeyboardInterrupt as exc:
            status, reason = "interrupted", str(exc) or "interrupted: stopped at once, rig made safe"
        except DeviceUnavailable as exc:
            status, reason = "failed", f"device unavailable: {exc}"
        finally:
            self.control.shutting_down = True
        lab_time_s = self.now()
        self.publish(RunEnded(status, reason, lab_time_s, counts["done"], counts["retries"]))
        return SessionResult(
            status=status,
            reason=reason,
            done=counts["done"],
            executed=counts["executed"],
            silent=counts["silent"],
            retries=counts["retries"],
            lab_time_s=lab_time_s,
        )

    def _run_pass(
        self, trials: Sequence[TrialLike], counts: dict[str, int], attempts: Mapping[str, int]
    ) -> tuple[str, str] | None:
        blocked = self.rig.batches
        for block in self._blocks(trials) if blocked else [trials]:
            if blocked:
                self.rig.prepare(block)
            outcome = self.run_block(block, counts, attempts)
            if blocked:
                self.publish(BlockEnded(len(block), self.now()))
            if outcome is not None:
                return outcome
        return None

    def _blocks(self, trials: Sequence[TrialLike]) -> list[Sequence[TrialLike]]:
        size = max(1, self.block_trials)
        return [trials[i : i + size] for i in range(0, len(trials), size)]

    def run_block(
        self, trials: Sequence[TrialLike], counts: dict[str, int], attempts: Mapping[str, int] | None = None,
    ) -> tuple[str, str] | None:
        """Run trials one by one, updating `counts`; (status, reason) if the run must end.

        The keys of `counts`: executed, silent, retries, done (see `SessionResult`). `attempts`
        gives the first attempt of trials pressed again (1 for the others).
        """
        for trial in trials:
            if self.control.requested is not None:
                return "interrupted", self.control.requested
            outcome = self._trial(trial, counts, (attempts or {}).get(trial.trial_id, 1))
            if outcome is not None:
                return outcome
        return None

    def _trial(self, trial: TrialLike, counts: dict[str, int], attempt: int = 1) -> tuple[str, str] | None:
        """Run one trial with retries; returns (status, reason) if the run must end."""
        parameters = read_parameters(trial)
        while True:
            t_start_s = self.now()
            self.publish(TrialStarted(trial.trial_id, trial.index, attempt, parameters, t_start_s))
            try:
                result = self.rig.keystroke(trial, attempt)
            except ConnectionLost as exc:
                error = f"connection lost: {exc}"
                if attempt >= self.retry.max_attempts:
                    self._done(failed_trial(trial, attempt, f"{error} (after {attempt} attempts)", t_start_s, motion=self.motion), counts)
                    return "failed", f"trial {trial.index} ({trial.trial_id}): {error} after {attempt} attempts"
                next_attempt = self._retry(trial, attempt, error, counts)
                if next_attempt < 0:
                    error = f"could not reconnect to the arm after {self.retry.max_attempts} attempts"
                    self._done(failed_trial(trial, self.retry.max_attempts, error, t_start_s, motion=self.motion), counts)
                    return "failed", f"trial {trial.index} ({trial.trial_id}): {error}"
                attempt = next_attempt
                continue
            except SafetyStop as exc:
                reason = f"safety stop at trial {trial.index} ({trial.trial_id}): {exc}"
                self.publish(TrialStopped(trial.trial_id, trial.index, attempt, reason, self.now()))
                return "stopped", reason
            except SafetyViolation as exc:
                # Refused before anything moved: record it and go on with the next trial.
                self._done(failed_trial(trial, attempt, f"refused: {exc}", t_start_s, motion=self.motion), counts)
                return None
            data = read_keystroke(
                trial, attempt, result, clock_offset_s=self.clock_offset_s, record=self.record,
                motion=self.motion,
            )
            again = data.note_on_lost and attempt < self.retry.max_attempts
            if again:  # its samples and MIDI come with the keystroke that replaces it
                data = replace(data, samples=(), midi=())
            self._done(data, counts)
            if again:
                counts["retries"] += 1
                self.publish(TrialRetried(trial.trial_id, trial.index, attempt,
                                          str(data.row["error"]), 0.0, self.now()))
                self.redo.append((trial, attempt + 1))
            return None

    def _retry(self, trial: TrialLike, attempt: int, error: str, counts: dict[str, int]) -> int:
        """Wait, reconnect and return the next attempt number (-1 if retries ran out)."""
        while True:
            backoff_s = self.retry.backoff_before(attempt + 1)
            counts["retries"] += 1
            self.publish(TrialRetried(trial.trial_id, trial.index, attempt, error, backoff_s, self.now()))
            self.rig.clock.sleep(backoff_s)
            attempt += 1
            try:
                self.rig.reconnect()
                return attempt
            except ConnectionLost as exc:
                error = f"reconnect failed: {exc}"
                if attempt >= self.retry.max_attempts:
                    return -1

    def _done(self, data: TrialData, counts: dict[str, int]) -> None:
        counts["executed"] += 1
        if data.status != "failed":
            counts["done"] += 1
        if data.status == "silent":
            counts["silent"] += 1
        self.publish(TrialDone(data, self.now()))


def read_parameters(trial: TrialLike) -> dict[str, float]:
    """The parameters shown while a trial runs (progress bar, journal)."""
    return {k: v for k, v in parameters_of(trial).items() if isinstance(v, int | float) and k not in SEQUENCE_COLUMNS}
