"""StoreSink: the subscriber that writes a run's records to its run folder.

Trials are written in batches (every `batch_trials` trials or `batch_s` wall seconds, whichever
comes first; on a simulated rig, one batch per block of trials the rig prepared together) so a 2,000-trial sim sweep is not 6,000 tiny files, while a kill -9 loses at most
the batch in memory. Order on disk, which resume relies on:

1. `started` is journalled before the arm moves (durable with the next flush); on a simulated
   rig that works out blocks, a block's `started` lines are written together, right before its
   part (nothing moves; a kill loses the block either way and resume redoes it);
2. the batch's samples and midi parts, then its trials part, land atomically;
3. only then are the batch's `done` lines journalled (one fsync).

So the journal never claims a trial the data lacks; a trial whose data landed but whose `done`
line did not is found by resume from the parts themselves.
"""

from __future__ import annotations

import time
from typing import Any

from pianobot.run.records import (
    BlockEnded,
    Record,
    RunEnded,
    RunStarted,
    TrialDone,
    TrialRetried,
    TrialStarted,
    TrialStopped,
)
from pianobot.run.rows import TrialData, midi_table, samples_table, trials_table
from pianobot.store import RunWriter, StagedPart


class StoreSink:
    """Writes records to a RunWriter: journal lines, part batches, run.json progress."""

    def __init__(self, writer: RunWriter, *, batch_trials: int = 50, batch_s: float = 2.0) -> None:
        self.writer = writer
        self.batch_trials = max(1, batch_trials)
        self.batch_s = batch_s
        self._batch: list[TrialData] = []
        self._last_flush = time.monotonic()
        self._lab_time_s = 0.0
        self._blocks = False  # a batching rig: one part per block (at BlockEnded), whatever it takes
        self._started: list[tuple[str, dict[str, Any]]] = []  # a block's `started` lines, not yet written

    def __call__(self, record: Record) -> None:
        if isinstance(record, TrialStarted):
            fields = {"trial_id": record.trial_id, "index": record.index,
                      "attempt": record.attempt, "t_s": record.t_s}
            if self._blocks:
                self._started.append(("started", fields))  # journalled with the block's part
            else:
                self.writer.journal_deferred("started", **fields)
        elif isinstance(record, TrialRetried):
            self._journal_started()
            self.writer.journal(
                "retried", trial_id=record.trial_id, index=record.index, attempt=record.attempt,
                error=record.error, backoff_s=record.backoff_s, t_s=record.t_s,
            )
        elif isinstance(record, TrialDone):
            self._batch.append(record.data)
            self._lab_time_s = record.lab_time_s
            if self._blocks:
                pass  # the block is written as one part at its end
            elif record.status == "failed":
                self.flush()  # a failure is rare and worth having on disk at once
            elif len(self._batch) >= self.batch_trials or (
                time.monotonic() - self._last_flush >= self.batch_s
            ):
                self.flush()
        elif isinstance(record, BlockEnded):
            self._lab_time_s = record.lab_time_s
            self.flush(record.parts)
        elif isinstance(record, TrialStopped):
            self.flush()
            self.writer.journal(
                "failed", trial_id=record.trial_id, index=record.index, attempt=record.attempt,
                error=record.reason, kind="safety_stop", t_s=record.t_s,
            )
        elif isinstance(record, RunStarted):
            self._blocks = record.blocks
            self.writer.journal(
                "resumed" if record.resumed else "run_started",
                planned=record.planned, done=record.done, todo=record.todo,
                **({"warnings": list(record.warnings)} if record.warnings else {}),
            )
        elif isinstance(record, RunEnded):
            self._lab_time_s = record.lab_time_s
            self.flush()
            self.writer.journal(
                "run_ended", status=record.status, reason=record.reason, done=record.done,
                retries=record.retries, lab_time_s=record.lab_time_s,
            )

    def flush(self, encoded: dict[str, bytes | StagedPart] | None = None) -> None:
        """Write the pending batch as one part set, then journal its trials as done/failed.

        `encoded`: the batch's parts as a worker encoded (or staged) them (its records carry
        rows only).
        """
        self._last_flush = time.monotonic()
        self._journal_started()
        if not self._batch:
            return
        batch, self._batch = self._batch, []
        if encoded is not None:
            part = self.writer.append_encoded(encoded)
        else:
            part = self.writer.append(trials_table(batch), samples_table(batch), midi_table(batch))
        events: list[tuple[str, dict[str, Any]]] = [
            (
                "failed" if d.status == "failed" else "done",
                {
                    "trial_id": d.trial_id,
                    "index": d.row["index"],
                    "attempt": d.row["attempt"],
                    "status": d.status,
                    "part": part,
                    **({"error": d.row.get("error")} if d.status == "failed" else {}),
                },
            )
            for d in batch
        ]
        self.writer.journal_many(events)
        self.writer.update_meta(lab_time_s=self._lab_time_s)

    def _journal_started(self) -> None:
        """Write the pending `started` lines of a block (in order, before anything after them)."""
        if self._started:
            started, self._started = self._started, []
            self.writer.journal_many(started, sync=False)
