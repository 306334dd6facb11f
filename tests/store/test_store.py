"""The dataset store: round trip, live reads while parts exist, atomic parts, compaction."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

import pianobot
from pianobot.errors import InputError
from pianobot.store import RunLocked, RunWriter, list_runs, load_run, read_journal
from pianobot.store.layout import RunPaths, slugify
from pianobot.store.schema import SCHEMA_VERSION, TRIALS_SCHEMA


def _trials(ids: list[str], status: str = "ok", attempt: int = 1) -> pd.DataFrame:
    return pd.DataFrame(
        {
            "trial_id": ids,
            "index": range(len(ids)),
            "attempt": [attempt] * len(ids),
            "status": [status] * len(ids),
            "note": [60] * len(ids),
            "vacuum_kpa": [-20.0] * len(ids),
            "down_velocity_mps": np.linspace(0.01, 0.05, len(ids)),
            "on_velocity": [64.0] * len(ids),
            "n_note_on": [1] * len(ids),
        }
    )


def _samples(ids: list[str], n: int = 5) -> pd.DataFrame:
    rows = [
        {"trial_id": t, "source": "arm", "t_s": i * 0.002, "x0_m": i * 1e-3}
        for t in ids
        for i in range(n)
    ]
    return pd.DataFrame(rows)


def _midi(ids: list[str]) -> pd.DataFrame:
    return pd.DataFrame(
        [{"trial_id": t, "t_s": 1.0 + k, "type": "note_on", "note": 60, "velocity": 70} for k, t in enumerate(ids)]
    )


def _plan(ids: list[str]) -> pd.DataFrame:
    return pd.DataFrame({"trial_id": ids, "index": range(len(ids))})


def _create(data_dir: Path, ids: list[str], name: str = "Store Test") -> RunWriter:
    return RunWriter.create(
        data_dir, name=name, kind="sweep", meta={"seed": 7, "spec_sha256": "abc"}, plan=_plan(ids)
    )


def test_round_trip_writes_layout_and_metadata(data_dir: Path) -> None:
    ids = [f"t{i}" for i in range(6)]
    with _create(data_dir, ids) as writer:
        assert "-store-test-" in writer.run_id
        writer.journal("started", trial_id="t0")
        writer.append(_trials(ids[:3]), _samples(ids[:3]), _midi(ids[:3]))
        writer.append(_trials(ids[3:], status="silent"), _samples(ids[3:]), None)
        writer.finish("completed", lab_time_s=12.5)
        root = writer.path
    assert sorted(p.name for p in root.iterdir()) == [
        "journal.jsonl", "midi.parquet", "parts", "plan.parquet", "run.json", "samples", "trials.parquet",
    ]
    assert list((root / "parts").iterdir()) == []
    # The samples are written once, one file per batch, and stay: a Parquet dataset folder.
    assert sorted(p.name for p in (root / "samples").iterdir()) == [
        "samples-000001.parquet", "samples-000002.parquet"]
    assert len(pd.read_parquet(root / "samples")) == 30
    run = load_run(root.name, data_dir)
    meta = run.meta
    assert meta["status"] == "completed" and meta["kind"] == "sweep" and meta["seed"] == 7
    assert meta["pianobot_version"] == pianobot.__version__
    assert meta["trials_planned"] == 6 and meta["end_utc"] is not None
    trials = run.trials
    assert list(trials.columns) == TRIALS_SCHEMA.names
    assert list(trials["trial_id"]) == ids
    assert set(trials["run_id"]) == {run.run_id}
    assert list(trials["status"]) == ["ok"] * 3 + ["silent"] * 3
    assert trials["off_velocity"].isna().all()
    assert len(run.samples) == 30 and set(run.samples["source"]) == {"arm"}
    assert run.samples["x2_m"].isna().all()
    assert list(run.midi["trial_id"]) == ids[:3]
    assert list(run.plan["trial_id"]) == ids
    for name in ("trials", "samples/samples-000001", "midi", "plan"):
        metadata = pq.read_schema(root / f"{name}.parquet").metadata
        assert metadata[b"pianobot.schema_version"] == SCHEMA_VERSION.encode()
    assert [e["event"] for e in run.journal] == ["started"]


def test_live_run_is_readable_from_parts(data_dir: Path) -> None:
    ids = [f"t{i}" for i in range(4)]
    writer = _create(data_dir, ids)
    writer.append(_trials(ids[:2]), _samples(ids[:2]), _midi(ids[:2]))
    writer.append(_trials(ids[2:3]), _samples(ids[2:3]))
    # Plain pyarrow/pandas on the parts folder works while the run is going.
    direct = pd.read_parquet(writer.path / "parts" / "trials-000001.parquet")
    assert list(direct["trial_id"]) == ids[:2]
    run = load_run(writer.run_id, data_dir)
    assert run.status == "running"
    assert list(run.trials["trial_id"]) == ids[:3]
    assert len(run.samples) == 15
    summary = list_runs(data_dir)[0]
    assert (summary.trials_done, summary.trials_planned, summary.status) == (3, 4, "running")
    writer.close()
    # What a kill -9 leaves: status 'running' and no live lock. The listing says the process died
    # (it used to look like a live run) and how to resume, with the data folder it is in.
    dead = list_runs(data_dir)[0]
    assert dead.status == "died" and f"--resume {writer.run_id} --data {data_dir}" in str(dead.reason)


def test_uncommitted_and_temporary_parts_are_invisible(data_dir: Path) -> None:
    ids = ["a", "b"]
    writer = _create(data_dir, ids)
    writer.append(_trials(ids[:1]), _samples(ids[:1]))
    parts, samples = writer.path / "parts", writer.path / "samples"
    # A killed writer: the samples part of batch 2 landed, its trials part did not, and a
    # half-written temp file lies around.
    shutil.copy(samples / "samples-000001.parquet", samples / "samples-000002.parquet")
    (parts / ".trials-000002.parquet.123.abc.tmp").write_bytes(b"PAR1 torn")
    run = load_run(writer.run_id, data_dir)
    assert len(run.samples) == 5 and list(run.trials["trial_id"]) == ["a"]
    writer.close()
    # Reopening (resume) removes the orphan and continues numbering after the committed batch.
    writer = RunWriter.reopen(data_dir, writer.run_id)
    assert not (samples / "samples-000002.parquet").exists()
    assert not (parts / ".trials-000002.parquet.123.abc.tmp").exists()
    assert writer.append(_trials(["b"]), _samples(["b"])) == 2
    writer.finish("completed")
    assert list(load_run(writer.run_id, data_dir).trials["trial_id"]) == ids
    writer.close()


def test_compaction_interrupted_before_parts_removed_counts_once(data_dir: Path) -> None:
    ids = ["a", "b", "c"]
    writer = _create(data_dir, ids)
    writer.append(_trials(ids[:2]), _samples(ids[:2]), _midi(ids[:2]))
    parts = writer.path / "parts"
    saved = {p.name: p.read_bytes() for p in parts.iterdir()}
    writer.compact()
    for name, data in saved.items():  # as if killed after compacting, before the unlinks
        (parts / name).write_bytes(data)
    run = load_run(writer.run_id, data_dir)
    assert list(run.trials["trial_id"]) == ["a", "b"]
    assert len(run.samples) == 10 and len(run.midi) == 2
    writer.append(_trials(ids[2:]), _samples(ids[2:]), _midi(ids[2:]))
    writer.finish("completed")
    run = load_run(writer.run_id, data_dir)
    assert list(run.trials["trial_id"]) == ids and len(run.samples) == 15 and len(run.midi) == 3
    writer.close()


def test_samples_are_written_once_and_stay_committed_after_compaction(data_dir: Path) -> None:
    """Compaction merges trials and midi only: the samples files keep their bytes, count as
    committed through trials.parquet, and a resumed run adds files beside them."""
    from pianobot.store import check_run

    ids = ["a", "b", "c"]
    writer = _create(data_dir, ids)
    writer.append(_trials(ids[:2]), _samples(ids[:2]), _midi(ids[:2]))
    samples = writer.path / "samples" / "samples-000001.parquet"
    written = samples.read_bytes()
    writer.finish("stopped", reason="operator")
    writer.close()
    assert samples.read_bytes() == written  # not re-encoded
    assert not list((writer.path / "parts").glob("trials-*.parquet"))
    run = load_run(writer.run_id, data_dir)
    assert len(run.samples) == 10 and check_run(run.paths).ok
    # Resume: the orphan cleanup keeps the files of batches trials.parquet holds.
    writer = RunWriter.reopen(data_dir, writer.run_id)
    assert samples.exists()
    writer.update_meta(status="running", reason=None)
    writer.append(_trials(ids[2:]), _samples(ids[2:]), _midi(ids[2:]))
    writer.finish("completed")
    writer.close()
    run = load_run(writer.run_id, data_dir)
    assert sorted(set(run.samples["trial_id"])) == ids and len(run.samples) == 15
    assert list(run.trials["trial_id"]) == ids and check_run(run.paths).ok


def test_a_check_without_the_journal_says_the_bytes_were_not_verified(data_dir: Path) -> None:
    """A missing or emptied journal leaves nothing to check SHA-256 against: the files are read,
    and the check says so (it used to say "intact ... checked against the journal")."""
    from pianobot.store import check_run

    writer = _create(data_dir, ["a", "b"])
    writer.append(_trials(["a", "b"]), _samples(["a", "b"]), _midi(["a", "b"]))
    writer.finish("completed")
    writer.close()
    paths = RunPaths(writer.path)
    assert check_run(paths).ok and check_run(paths).unrecorded == 0
    paths.journal.write_text("")
    emptied = check_run(paths)
    assert emptied.ok and emptied.unrecorded > 0
    assert any("journal.jsonl is empty" in note and "only read" in note for note in emptied.notes)
    paths.journal.unlink()
    assert any("journal.jsonl is missing" in note for note in check_run(paths).notes)


def test_a_deleted_trials_table_is_damage_even_to_the_quick_check(data_dir: Path) -> None:
    """`pianobot runs` listed a run whose trials.parquet was deleted as 'completed 0/N'."""
    from pianobot.store import check_run

    writer = _create(data_dir, ["a", "b"])
    writer.append(_trials(["a", "b"]), _samples(["a", "b"]), _midi(["a", "b"]))
    writer.finish("completed")
    writer.close()
    (writer.path / "trials.parquet").unlink()
    quick = check_run(RunPaths(writer.path), deep=False)
    assert not quick.ok and "trials.parquet is missing (run.json counts 2 trials)" in quick.reason
    assert list_runs(data_dir)[0].status == "damaged"


def test_a_journal_line_naming_an_unknown_table_is_checked_not_crashed_on(data_dir: Path) -> None:
    """A flipped byte that leaves a part line readable JSON (`"tr3als"`; found by the fuzz test):
    the check and the reader go on with the tables they know."""
    from pianobot.store import check_run

    writer = _create(data_dir, ["a", "b"])
    writer.append(_trials(["a", "b"]), _samples(["a", "b"]), _midi(["a", "b"]))
    writer.close()
    journal = writer.path / "journal.jsonl"
    lines = journal.read_text().splitlines()
    part = next(i for i, line in enumerate(lines) if json.loads(line).get("event") == "part")
    assert '"trials":' in lines[part]
    lines[part] = lines[part].replace('"trials":', '"tr3als":', 1)
    journal.write_text("\n".join(lines) + "\n")
    report = check_run(RunPaths(writer.path))
    assert report.files_checked > 0
    assert sorted(load_run(writer.run_id, data_dir).trials["trial_id"]) == ["a", "b"]


def test_a_run_with_samples_parts_of_an_older_pianobot_reads_and_resumes(data_dir: Path) -> None:
    """Samples parts in parts/ (where an older pianobot wrote them) are read and kept."""
    writer = _create(data_dir, ["a", "b"])
    writer.append(_trials(["a"]), _samples(["a"]))
    writer.close()
    old = writer.path / "parts" / "samples-000001.parquet"
    os.replace(writer.path / "samples" / "samples-000001.parquet", old)
    shutil.rmtree(writer.path / "samples")
    writer = RunWriter.reopen(data_dir, writer.run_id)
    writer.append(_trials(["b"]), _samples(["b"]))
    writer.finish("completed")
    writer.close()
    run = load_run(writer.run_id, data_dir)
    assert old.exists() and sorted(set(run.samples["trial_id"])) == ["a", "b"]


def test_repair_of_a_finished_run_takes_out_the_trials_whose_samples_were_lost(data_dir: Path) -> None:
    """Two damaged samples files of a compacted run: their trials and MIDI leave trials.parquet
    and midi.parquet (the originals kept in quarantine, once), and a resume redoes them."""
    from pianobot.store import check_run
    from pianobot.store.repair import repair_run

    ids = ["a", "b", "c", "d"]
    writer = _create(data_dir, ids)
    for batch in (ids[:2], ids[2:3], ids[3:]):
        writer.append(_trials(batch), _samples(batch), _midi(batch))
    writer.finish("completed")
    writer.close()
    root = writer.path
    original = {name: (root / f"{name}.parquet").read_bytes() for name in ("trials", "midi")}
    for batch in (1, 3):
        part = root / "samples" / f"samples-{batch:06d}.parquet"
        part.write_bytes(part.read_bytes()[:100])
    report = repair_run(RunPaths(root))
    assert report.ok and report.lost_batches == [1, 3] and report.trials_lost == 3
    run = load_run(root.name, data_dir)
    assert run.status == "interrupted"
    assert list(run.trials["trial_id"]) == ["c"] and list(run.midi["trial_id"]) == ["c"]
    assert set(run.samples["trial_id"]) == {"c"}
    for name, data in original.items():
        (kept,) = (root / "quarantine").rglob(f"{name}.parquet")
        assert kept.read_bytes() == data
    writer = RunWriter.reopen(data_dir, root.name)
    lost = ["a", "b", "d"]
    writer.append(_trials(lost), _samples(lost), _midi(lost))
    writer.finish("completed")
    writer.close()
    run = load_run(root.name, data_dir)
    assert sorted(run.trials["trial_id"]) == ids and sorted(run.midi["trial_id"]) == ids
    assert run.samples.groupby("trial_id").size().to_dict() == dict.fromkeys(ids, 5)
    assert check_run(run.paths).ok


def test_resume_after_finish_appends_and_recompacts(data_dir: Path) -> None:
    writer = _create(data_dir, ["a", "b"])
    writer.append(_trials(["a"]))
    writer.finish("stopped", reason="protective stop")
    writer.close()
    assert load_run(writer.run_id, data_dir).meta["reason"] == "protective stop"
    writer = RunWriter.reopen(data_dir, writer.run_id)
    writer.update_meta(status="running", reason=None)
    writer.append(_trials(["b"]))
    assert list(load_run(writer.run_id, data_dir).trials["trial_id"]) == ["a", "b"]
    writer.finish("completed")
    writer.close()
    assert list(load_run(writer.run_id, data_dir).trials["trial_id"]) == ["a", "b"]


def test_redone_trial_keeps_its_last_row(data_dir: Path) -> None:
    writer = _create(data_dir, ["a", "b"])
    writer.append(_trials(["a", "b"], status="failed", attempt=3))
    writer.append(_trials(["b"], status="ok", attempt=1))
    live = load_run(writer.run_id, data_dir).trials
    writer.finish("completed")
    writer.close()
    final = load_run(writer.run_id, data_dir).trials
    for frame in (live, final):
        assert list(frame["trial_id"]) == ["a", "b"]
        assert list(frame["status"]) == ["failed", "ok"]


def test_run_ids_resolve_by_prefix_and_unknown_ids_say_how_to_list(data_dir: Path) -> None:
    first = _create(data_dir, ["a"], name="alpha")
    second = _create(data_dir, ["a"], name="beta")
    for writer in (first, second):
        writer.close()
    assert load_run(first.run_id, data_dir).run_id == first.run_id
    assert load_run(first.run_id[:-2], data_dir).run_id == first.run_id
    with pytest.raises(InputError, match="pianobot runs"):
        load_run("no-such-run", data_dir)
    with pytest.raises(InputError, match="matches 2 runs"):
        load_run(first.run_id[:8], data_dir)
    with pytest.raises(InputError):
        load_run("../x", data_dir)


def test_list_runs_summarizes_status_silent_and_lab_time(data_dir: Path) -> None:
    assert list_runs(data_dir) == []
    writer = _create(data_dir, ["a", "b", "c", "d"])
    writer.append(_trials(["a", "b", "c"]))
    writer.append(_trials(["d"], status="silent"))
    writer.finish("completed", lab_time_s=42.0)
    writer.close()
    (summary,) = list_runs(data_dir)
    assert summary.status == "completed" and summary.trials_done == 4
    assert summary.silent_pct == pytest.approx(25.0)
    assert summary.lab_time_s == pytest.approx(42.0)
    assert json.loads(json.dumps(summary.to_dict()))["run_id"] == writer.run_id


def test_journal_appends_fsynced_lines_and_skips_a_torn_tail(data_dir: Path) -> None:
    writer = _create(data_dir, ["a"])
    writer.journal("started", trial_id="a", attempt=1)
    writer.journal("done", trial_id="a", value=float("nan"))
    writer.close()
    path = writer.path / "journal.jsonl"
    with open(path, "ab") as handle:
        handle.write(b'{"event": "started", "trial_id": "b"')  # killed mid-line
    events = read_journal(path)
    assert [e["event"] for e in events] == ["started", "done"]
    assert events[1]["value"] is None and "t_utc" in events[0]
    writer = RunWriter.reopen(data_dir, writer.run_id)
    writer.journal("resumed")
    writer.close()
    assert [e["event"] for e in read_journal(path)] == ["started", "done", "resumed"]


def test_a_live_writer_locks_the_run(data_dir: Path) -> None:
    writer = _create(data_dir, ["a"])
    paths = RunPaths(writer.path)
    record = json.loads(paths.lock.read_text())
    assert record["pid"] == os.getpid() and record["host"] and record["start_utc"]
    writer.close()
    paths.lock.write_text("1\n")  # an old-style lock of pid 1, which is alive
    with pytest.raises(RunLocked):
        RunWriter.reopen(data_dir, writer.run_id)
    paths.lock.write_text("999999999\n")  # a dead writer's lock is taken over
    RunWriter.reopen(data_dir, writer.run_id).close()
    assert not paths.lock.exists()


def test_bad_tables_are_refused(data_dir: Path) -> None:
    writer = _create(data_dir, ["a"])
    with pytest.raises(ValueError, match="trial_id"):
        writer.append(pd.DataFrame({"status": ["ok"]}))
    with pytest.raises(ValueError, match="unknown column"):
        writer.append(_trials(["a"]), samples=_samples(["a"]).assign(force_n=1.0))
    with pytest.raises(ValueError, match="kind"):
        RunWriter.create(data_dir, name="x", kind="nope", meta={}, plan=None)
    writer.close()


def test_slugify_makes_safe_names() -> None:
    assert slugify("Soft grid #2 / -80 kPa") == "soft-grid-2-80-kpa"
    assert slugify("!!!") == "run"
