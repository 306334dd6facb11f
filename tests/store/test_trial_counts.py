"""Trial counts in run.json: `pianobot runs` lists a run without reading its tables, and never
shows counts that differ from the trials table (a redone trial counts once, as it ended last)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

import pianobot.store.tables as tables
from pianobot.store import RunWriter, list_runs, load_run
from pianobot.store.layout import RunPaths
from pianobot.store.reader import Run, trial_counts
from pianobot.store.repair import repair_run


def _trials(ids: list[str], status: str) -> pd.DataFrame:
    return pd.DataFrame({"trial_id": ids, "index": range(len(ids)), "attempt": 1,
                         "status": status, "note": 60})


def _table_counts(run: Run) -> dict[str, int]:
    return tables.trial_status_counts(run.paths)


def _counts_without_the_table(run: Run, monkeypatch: pytest.MonkeyPatch) -> dict[str, int]:
    """`trial_counts`, failing the test if it had to read the trials table."""
    with monkeypatch.context() as patch:
        patch.setattr(tables, "trial_status_counts", _refuse)
        return trial_counts(run)


def _refuse(paths: RunPaths) -> dict[str, int]:
    raise AssertionError("the trials table was read although run.json's counts were current")


def _append(writer: RunWriter, ids: list[str], status: str) -> None:
    """One batch as the runner writes it: the part, then run.json (the lab time)."""
    writer.append(_trials(ids, status))
    writer.update_meta(lab_time_s=1.0)


def test_counts_follow_a_run_through_failures_resume_and_compaction(
    data_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    plan = pd.DataFrame({"trial_id": list("abcdef"), "index": range(6)})
    writer = RunWriter.create(data_dir, name="counts", kind="sweep", meta={}, plan=plan)
    _append(writer, ["a", "b"], "ok")
    _append(writer, ["c", "d"], "failed")
    run = load_run(writer.run_id, data_dir)
    assert _counts_without_the_table(run, monkeypatch) == {"ok": 2, "silent": 0, "failed": 2}
    writer.finish("interrupted", reason="kill")
    writer.close()
    writer = RunWriter.reopen(data_dir, run.run_id)  # resume: c and d are redone
    _append(writer, ["c", "d", "e"], "silent")
    _append(writer, ["f"], "ok")
    expected = {"ok": 3, "silent": 3, "failed": 0}
    assert _counts_without_the_table(run, monkeypatch) == expected == _table_counts(run)
    writer.finish("completed")  # compacted: the parts are gone, trials.parquet holds them
    writer.close()
    assert not run.paths.part_batches()["trials"]
    assert _counts_without_the_table(run, monkeypatch) == expected == _table_counts(run)
    (summary,) = list_runs(data_dir)
    assert (summary.trials_done, summary.failed, summary.silent_pct) == (6, 0, 50.0)


def test_counts_behind_the_last_batch_are_not_trusted(data_dir: Path) -> None:
    """A run killed after a part landed but before run.json was written again."""
    writer = RunWriter.create(data_dir, name="behind", kind="sweep", meta={}, plan=None)
    _append(writer, ["a"], "ok")
    writer.append(_trials(["b", "c"], "silent"))  # no run.json write follows
    run = load_run(writer.run_id, data_dir)
    assert run.meta["trial_counts"]["batch"] == 1
    assert trial_counts(run) == {"ok": 1, "silent": 2, "failed": 0}
    writer.close()


def test_a_repaired_run_is_counted_from_its_table(data_dir: Path) -> None:
    writer = RunWriter.create(data_dir, name="repaired", kind="sweep", meta={}, plan=None)
    _append(writer, ["a", "b"], "ok")
    _append(writer, ["c"], "silent")
    writer.close()
    run = load_run(writer.run_id, data_dir)
    part = run.paths.part("trials", 2)
    part.write_bytes(part.read_bytes()[:60])  # damaged; the journal's copy restores it
    assert repair_run(run.paths).ok
    assert run.meta["trial_counts"] is None
    assert trial_counts(run) == {"ok": 2, "silent": 1, "failed": 0} == _table_counts(run)


def test_counts_that_are_not_numbers_are_not_used(data_dir: Path) -> None:
    """A run.json edited by hand (or by another tool): the table decides."""
    import json

    writer = RunWriter.create(data_dir, name="edited", kind="sweep", meta={}, plan=None)
    _append(writer, ["a", "b"], "ok")
    writer.close()
    run = load_run(writer.run_id, data_dir)
    meta = run.meta
    meta["trial_counts"] = {"ok": "2", "silent": None, "failed": 0, "batch": 1}
    run.paths.run_json.write_text(json.dumps(meta))
    assert trial_counts(run) == {"ok": 2, "silent": 0, "failed": 0}
    (summary,) = list_runs(data_dir)
    assert summary.trials_done == 2
